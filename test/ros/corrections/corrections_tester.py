#!/usr/bin/env python3
"""Loop-closure rostest (test/ros/corrections.test): frames with drifting poses of a body frame,
then a nav_msgs/Path of the true trajectory; the node's final selection must equal select_views's
on the folder, whose poses are that true trajectory.

Tolerances: keyframe poses to 1e-9 (the path's pose composed with the extrinsic); E to 1e-6
relative (the points were back-projected with the drifted pose and moved with the keyframe, so
they equal the folder's to rounding); next view sets, order, completion and pairs exactly.
"""
import json
import math
import os
import shutil
import sys
import tempfile
import time
import unittest

import numpy
import rospy
import rostest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'replay'))
from replay_tester import Replay, find_tool, msg_stamp_ns, run, stamp_ns  # noqa: E402

from geometry_msgs.msg import PoseStamped, TransformStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from view_selection.msg import InputStatistics, ViewSelection  # noqa: E402
from view_selection.srv import GetSelection  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

PKG = 'view_selection'
# camera_link (x forward, y left, z up) <- optical frame (z forward, x right, y down), 3 cm off.
EXTRINSIC_T = numpy.array([0.03, -0.01, 0.02])
EXTRINSIC_Q = numpy.array([-0.5, 0.5, -0.5, 0.5])  # x, y, z, w


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return numpy.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                        aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def qconj(q):
    return numpy.array([-q[0], -q[1], -q[2], q[3]])


def rotate(q, v):
    return qmul(qmul(q, numpy.array([v[0], v[1], v[2], 0.0])), qconj(q))[:3]


def compose(a, b):
    """(t, q) of a * b."""
    return a[0] + rotate(a[1], b[0]), qmul(a[1], b[1])


def inverse(a):
    qi = qconj(a[1])
    return -rotate(qi, a[0]), qi


def yaw(angle):
    return numpy.array([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)])


def ros_time(stamp):
    ns = stamp_ns(stamp)
    return rospy.Time(ns // 1000000000, ns % 1000000000)


def pose_msg(t, q, stamp, frame='world'):
    m = PoseStamped()
    m.header.stamp, m.header.frame_id = stamp, frame
    m.pose.position.x, m.pose.position.y, m.pose.position.z = t
    m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = q
    return m


class Corrections(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.node = rospy.get_param('~node')
        cls.dataset = rospy.get_param('~dataset')
        cls.frames = int(rospy.get_param('~frames', 60))
        cls.timeout = float(rospy.get_param('~timeout', 60.0))
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_corrections_')
        cls.skip_reason = None
        if not os.path.isfile(os.path.join(cls.dataset, 'groundtruth.txt')):
            cls.skip_reason = 'no TUM folder at %s' % cls.dataset
            return
        select_views = find_tool('select_views')
        if not select_views:
            raise AssertionError('select_views is not built')
        offline = os.path.join(cls.tmp, 'offline')
        run([select_views, '--dataset', cls.dataset, '--max-frames', str(cls.frames), '--out', offline, '--quiet',
             '--print-sets', '0'] + Replay.select_views_options(cls.node), 600, 'select_views')
        with open(os.path.join(offline, 'selection.json')) as f:
            cls.expected = json.load(f)
        cls.selections = []
        rospy.Subscriber(cls.node + '/selection', ViewSelection, cls.selections.append)
        cls.run_sequence()

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    @classmethod
    def read(cls, name):
        rows = []
        with open(os.path.join(cls.dataset, name)) as f:
            for line in f:
                if line.strip() and not line.startswith('#'):
                    rows.append(line.split())
        return rows

    @classmethod
    def run_sequence(cls):
        import cv2
        rgb, depth = cls.read('rgb.txt')[:cls.frames], cls.read('depth.txt')[:cls.frames]
        truth = {round(float(r[0]), 6): (numpy.array([float(x) for x in r[1:4]]),
                                         numpy.array([float(x) for x in r[4:8]])) for r in cls.read('groundtruth.txt')}
        with open(os.path.join(cls.dataset, 'camera.yaml')) as f:
            k = dict(line.split(':') for line in f if ':' in line and not line.startswith('#'))
        fx, fy, cx, cy = (float(k[n]) for n in ('fx', 'fy', 'cx', 'cy'))
        width, height = int(k['width']), int(k['height'])

        static = rospy.Publisher('/tf_static', TFMessage, queue_size=1, latch=True)
        t = TransformStamped()
        t.header.stamp, t.header.frame_id, t.child_frame_id = rospy.Time.now(), 'camera_link', 'openni_rgb_optical_frame'
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = EXTRINSIC_T
        (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
         t.transform.rotation.w) = EXTRINSIC_Q
        static.publish(TFMessage(transforms=[t]))

        pubs = {n: rospy.Publisher('/drift/' + n, m, queue_size=100)
                for n, m in (('image', Image), ('camera_info', CameraInfo), ('depth', Image), ('pose', PoseStamped))}
        path_pub = rospy.Publisher('/drift/path', Path, queue_size=1, latch=True)
        deadline = time.time() + cls.timeout
        while time.time() < deadline and not all(p.get_num_connections() > 0 for p in pubs.values()):
            time.sleep(0.1)
        assert all(p.get_num_connections() > 0 for p in pubs.values()), 'the node did not subscribe'
        time.sleep(0.5)
        body_in_optical = inverse((EXTRINSIC_T, EXTRINSIC_Q))
        cls.true_body = []
        t0 = float(rgb[0][0])
        for q, ((s, rgb_path), (_, depth_path)) in enumerate(zip(rgb, depth)):
            stamp = ros_time(float(s))
            optical = truth[round(float(s), 6)]
            optical = (optical[0], optical[1] / numpy.linalg.norm(optical[1]))
            body = compose(optical, body_in_optical)
            cls.true_body.append((stamp, body))
            # Drift in the world: 3 cm/s and 1.5 deg/s, as odometry accumulates before a loop closes.
            dt = float(s) - t0
            drifted = compose((numpy.array([0.03 * dt, 0.0, -0.01 * dt]), yaw(math.radians(1.5 * dt))), body)
            pubs['pose'].publish(pose_msg(drifted[0], drifted[1], stamp))
            info = CameraInfo()
            info.header.stamp, info.header.frame_id = stamp, 'openni_rgb_optical_frame'
            info.width, info.height, info.distortion_model = width, height, 'plumb_bob'
            info.D = [0.0] * 5
            info.K = [fx, 0, cx, 0, fy, cy, 0, 0, 1]
            info.R = [1, 0, 0, 0, 1, 0, 0, 0, 1]
            info.P = [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]
            bgr = cv2.imread(os.path.join(cls.dataset, rgb_path), cv2.IMREAD_COLOR)
            png = cv2.imread(os.path.join(cls.dataset, depth_path), cv2.IMREAD_ANYDEPTH)
            metres = (png * (1.0 / 5000.0)).astype(numpy.float32)
            metres[png == 0] = numpy.nan
            for name, encoding, data, step in (('image', 'rgb8', bgr[:, :, ::-1].tobytes(), 3 * width),
                                               ('depth', '32FC1', metres.tobytes(), 4 * width)):
                m = Image()
                m.header.stamp, m.header.frame_id = stamp, 'openni_rgb_optical_frame'
                m.header.seq = q
                m.height, m.width, m.encoding, m.step, m.data = height, width, encoding, step, data
                pubs[name].publish(m)
            pubs['camera_info'].publish(info)
            time.sleep(0.05)
        cls.wait_stats(lambda s: s.frames_offered + s.frames_dropped >= cls.frames and s.images_in_synchroniser == 0,
                       'every frame handled')
        cls.before = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection
        path = Path()
        path.header.stamp, path.header.frame_id = rospy.Time.now(), 'world'
        for stamp, (tb, qb) in cls.true_body:
            path.poses.append(pose_msg(tb, qb, stamp))
        path_pub.publish(path)
        cls.stats = cls.wait_stats(lambda s: s.paths_applied >= 1, 'the path applied')
        time.sleep(0.5)  # ~selection is republished within ~publish_period
        cls.after = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection

    @classmethod
    def wait_stats(cls, predicate, what):
        deadline = time.time() + cls.timeout
        while time.time() < deadline:
            s = rospy.wait_for_message(cls.node + '/statistics', InputStatistics, timeout=cls.timeout)
            if predicate(s):
                return s
            time.sleep(0.2)
        raise AssertionError('%s: not within %.0f s (last statistics: %s)' % (what, cls.timeout, s))

    def setUp(self):
        if self.skip_reason:
            self.skipTest(self.skip_reason)

    def test_0_drifted_poses_differ_before_the_path(self):
        self.assertEqual(self.before.keyframes and len(self.before.keyframes), len(self.expected['keyframes']))
        last = self.before.keyframes[-1].pose.position
        x = self.expected['keyframes'][-1]['position']
        self.assertGreater(math.sqrt((last.x - x[0]) ** 2 + (last.y - x[1]) ** 2 + (last.z - x[2]) ** 2), 0.02,
                           'the drift should have moved the last keyframe by centimetres')

    def test_1_statistics(self):
        s = self.stats
        self.assertEqual(s.frames_dropped, 0, dict(zip(s.drop_reasons, s.drop_counts)))
        self.assertEqual(s.paths_applied, 1)
        # Every keyframe but the first (no drift yet) moved by more than the thresholds.
        self.assertEqual(s.keyframes_corrected, len(self.expected['keyframes']) - 1)

    def test_2_selection_after_the_path_equals_select_views_on_the_true_poses(self):
        s, e = self.after, self.expected
        self.assertEqual([msg_stamp_ns(k.stamp) for k in s.keyframes], [stamp_ns(k['stamp']) for k in e['keyframes']])
        for k, x in zip(s.keyframes, e['keyframes']):
            p, q = k.pose.position, k.pose.orientation
            for a, b in zip((p.x, p.y, p.z), x['position']):
                self.assertAlmostEqual(a, b, delta=1e-9)
            dot = abs(sum(a * b for a, b in zip((q.x, q.y, q.z, q.w), x['orientation_xyzw'])))
            self.assertGreater(dot, 1.0 - 1e-12)
            self.assertEqual(k.num_points, x['num_points'])
        matrix = e['error_resistance']
        for i, v in enumerate(s.next_view_sets):
            self.assertEqual(list(v.next_views), e['next_views'][i], 'C_%d' % i)
            for j, value in zip(v.next_views, v.error_resistance):
                self.assertLessEqual(abs(value - matrix[i][j]), 1e-6 * matrix[i][j], 'E[%d][%d]' % (i, j))
        self.assertEqual(list(s.order), e['order'])
        self.assertEqual([(c.view, c.added_to) for c in s.completed], [(c['view'], c['added_to']) for c in e['completed']])
        self.assertEqual([[p.first, p.second] for p in s.pairs], e['pairs'])
        finite = sum(1 for i, row in enumerate(matrix) for j, v in enumerate(row) if i != j and v is not None)
        self.assertEqual(s.finite_entries, finite)

    def test_3_selection_was_republished(self):
        self.assertTrue(self.selections, 'no ~selection message')
        last = self.selections[-1]
        self.assertEqual([[p.first, p.second] for p in last.pairs], self.expected['pairs'])
        x = self.expected['keyframes'][-1]['position']
        self.assertAlmostEqual(last.keyframes[-1].pose.position.x, x[0], delta=1e-9)


if __name__ == '__main__':
    rospy.init_node('corrections_tester')
    rostest.rosrun(PKG, 'corrections', Corrections, sys.argv)
