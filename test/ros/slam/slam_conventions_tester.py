#!/usr/bin/env python3
"""SLAM-system rostests (test/ros/slam_*.test): the package's launch file for one SLAM system,
fed as that system and its camera driver publish: their topic names, message types, frames and
body-frame conventions (ORB-SLAM2: PoseStamped in map of x-forward camera_link; ORB-SLAM3:
PoseStamped of the optical frame; RTAB-Map: tf map -> odom -> base_link -> camera, mapPath of
base_link; VINS-Fusion: Odometry of the IMU body, pose_graph_path). The frames are the built-in
synthetic sequence (generate_sequence: exact poses), so no data folder is needed.

Checks: every frame reaches the node and none is dropped; each keyframe's pose is the optical
frame's true pose (1e-6 m, 1e-6 rad) once the body-frame conventions are undone; for the systems
with a loop-closure path, poses drift first (the keyframes are off by centimetres) and the path
brings them back to the truth.
"""
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

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'corrections'))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'replay'))
from corrections_tester import compose, inverse, pose_msg, yaw  # noqa: E402
from replay_tester import find_tool, msg_stamp_ns, run, stamp_ns  # noqa: E402

from geometry_msgs.msg import PoseStamped, TransformStamped  # noqa: E402
from nav_msgs.msg import Odometry, Path  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402
from view_selection.msg import InputStatistics  # noqa: E402
from view_selection.srv import GetSelection  # noqa: E402

PKG = 'view_selection'
OPTICAL_FROM_X_FORWARD = numpy.array([-0.5, 0.5, -0.5, 0.5])  # x-forward frame <- optical frame

# Per system: inputs, the optical frame, the pose stream and its frames, the fixed chain from the
# body frame to the optical frame (parent, child, translation, rotation), the loop-closure path.
CONVENTIONS = {
    'orb_slam2': dict(image='/camera/rgb/image_raw', info='/camera/rgb/camera_info',
                      depth='/camera/depth_registered/image_raw', optical='camera_rgb_optical_frame',
                      pose=('/orb_slam2_rgbd/pose', 'pose_stamped', 'map', 'camera_link'),
                      chain=[('camera_link', 'camera_rgb_frame', (0.0, -0.045, 0.0), (0, 0, 0, 1)),
                             ('camera_rgb_frame', 'camera_rgb_optical_frame', (0, 0, 0), OPTICAL_FROM_X_FORWARD)],
                      path=None),
    'orb_slam3': dict(image='/camera/rgb/image_raw', info='/camera/rgb/camera_info',
                      depth='/camera/depth_registered/image_raw', optical='camera',
                      pose=('/orb_slam3/camera_pose', 'pose_stamped', 'world', 'camera'), chain=[], path=None),
    'rtabmap': dict(image='/camera/rgb/image_rect_color', info='/camera/rgb/camera_info',
                    depth='/camera/depth_registered/image_raw', optical='camera_rgb_optical_frame',
                    pose=('tf', 'tf', 'map', 'base_link'),
                    chain=[('base_link', 'camera_link', (0.1, 0.0, 0.3), (0, 0, 0, 1)),
                           ('camera_link', 'camera_rgb_optical_frame', (0.0, -0.045, 0.0), OPTICAL_FROM_X_FORWARD)],
                    path='/rtabmap/mapPath'),
    'vins_fusion': dict(image='/camera/color/image_raw', info='/camera/color/camera_info',
                        depth='/camera/aligned_depth_to_color/image_raw', optical='camera_color_optical_frame',
                        pose=('/vins_estimator/odometry', 'odometry', 'world', 'body'),
                        # IMU body: x forward; the camera 2 cm beside it, looking forward.
                        chain=[('body', 'camera_color_optical_frame', (0.02, 0.01, 0.0), OPTICAL_FROM_X_FORWARD)],
                        path='/loop_fusion/pose_graph_path'),
}


def transform(parent, child, t, q, stamp):
    m = TransformStamped()
    m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, parent, child
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = t
    m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, m.transform.rotation.w = q
    return m


class SlamConventions(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.node = rospy.get_param('~node')
        cls.name = rospy.get_param('~convention')
        cls.c = CONVENTIONS[cls.name]
        cls.frames = int(rospy.get_param('~frames', 40))
        cls.timeout = float(rospy.get_param('~timeout', 60.0))
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_slam_')
        generate = find_tool('generate_sequence')
        if not generate:
            raise AssertionError('generate_sequence is not built')
        cls.folder = os.path.join(cls.tmp, 'sequence')
        run([generate, '--out', cls.folder, '--frames', str(cls.frames), '--quiet'], 600, 'generate_sequence')
        cls.run_sequence()

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    @classmethod
    def rows(cls, name):
        with open(os.path.join(cls.folder, name)) as f:
            return [line.split() for line in f if line.strip() and not line.startswith('#')]

    @classmethod
    def run_sequence(cls):
        import cv2
        c = cls.c
        rgb, depth, truth = cls.rows('rgb.txt'), cls.rows('depth.txt'), cls.rows('groundtruth.txt')
        with open(os.path.join(cls.folder, 'camera.yaml')) as f:
            k = dict(line.split(':') for line in f if ':' in line and not line.startswith('#'))
        fx, fy, cx, cy = (float(k[n]) for n in ('fx', 'fy', 'cx', 'cy'))
        width, height = int(k['width']), int(k['height'])
        # body <- optical: the chain composed.
        optical_in_body = (numpy.zeros(3), numpy.array([0.0, 0.0, 0.0, 1.0]))
        for _, _, t, q in c['chain']:
            optical_in_body = compose(optical_in_body, (numpy.array(t, float), numpy.array(q, float)))
        body_in_optical = inverse(optical_in_body)

        tf_static = rospy.Publisher('/tf_static', TFMessage, queue_size=1, latch=True)
        tf = rospy.Publisher('/tf', TFMessage, queue_size=100)
        if c['chain']:
            tf_static.publish(TFMessage(transforms=[transform(p, ch, t, q, rospy.Time.now())
                                                    for p, ch, t, q in c['chain']]))
        pubs = {'image': rospy.Publisher(c['image'], Image, queue_size=100),
                'info': rospy.Publisher(c['info'], CameraInfo, queue_size=100),
                'depth': rospy.Publisher(c['depth'], Image, queue_size=100)}
        topic, kind, world, body_frame = c['pose']
        if kind == 'pose_stamped':
            pubs['pose'] = rospy.Publisher(topic, PoseStamped, queue_size=100)
        elif kind == 'odometry':
            pubs['pose'] = rospy.Publisher(topic, Odometry, queue_size=100)
        path_pub = rospy.Publisher(c['path'], Path, queue_size=1, latch=True) if c['path'] else None
        waiting = list(pubs.values()) + ([tf] if kind == 'tf' else [])
        deadline = time.time() + cls.timeout
        while time.time() < deadline and not all(p.get_num_connections() > 0 for p in waiting):
            time.sleep(0.1)
        assert all(p.get_num_connections() > 0 for p in waiting), 'the node did not subscribe to every input'
        time.sleep(0.5)

        cls.truth, cls.true_body = [], []
        t0 = float(rgb[0][0])
        for q, ((s, rgb_path), (_, depth_path), row) in enumerate(zip(rgb, depth, truth)):
            stamp = rospy.Time(int(stamp_ns(float(s)) // 1000000000), int(stamp_ns(float(s)) % 1000000000))
            optical = (numpy.array([float(x) for x in row[1:4]]), numpy.array([float(x) for x in row[4:8]]))
            optical = (optical[0], optical[1] / numpy.linalg.norm(optical[1]))
            cls.truth.append((stamp, optical))
            body = compose(optical, body_in_optical)
            cls.true_body.append((stamp, body))
            # With a loop-closure path the poses drift (4 cm/s, 2 deg/s) until the path corrects them.
            dt = float(s) - t0
            if c['path']:
                body = compose((numpy.array([0.04 * dt, 0.0, 0.02 * dt]), yaw(math.radians(2.0 * dt))), body)
            if kind == 'pose_stamped':
                pubs['pose'].publish(pose_msg(body[0], body[1], stamp, world))
            elif kind == 'odometry':
                m = Odometry()
                m.header = pose_msg(body[0], body[1], stamp, world).header
                m.child_frame_id = body_frame
                m.pose.pose = pose_msg(body[0], body[1], stamp, world).pose
                pubs['pose'].publish(m)
            else:  # tf: map -> odom (fixed here), odom -> base_link (the odometry)
                tf.publish(TFMessage(transforms=[transform('map', 'odom', (0, 0, 0), (0, 0, 0, 1), stamp),
                                                 transform('odom', body_frame, body[0], body[1], stamp)]))
            info = CameraInfo()
            info.header.stamp, info.header.frame_id = stamp, c['optical']
            info.width, info.height, info.distortion_model = width, height, 'plumb_bob'
            info.D = [0.0] * 5
            info.K = [fx, 0, cx, 0, fy, cy, 0, 0, 1]
            info.R = [1, 0, 0, 0, 1, 0, 0, 0, 1]
            info.P = [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]
            bgr = cv2.imread(os.path.join(cls.folder, rgb_path), cv2.IMREAD_COLOR)
            png = cv2.imread(os.path.join(cls.folder, depth_path), cv2.IMREAD_ANYDEPTH)
            millimetres = numpy.round(png.astype(numpy.float64) / 5.0).astype(numpy.uint16)  # 16UC1, as the drivers
            for name, encoding, data, step in (('image', 'rgb8', bgr[:, :, ::-1].tobytes(), 3 * width),
                                               ('depth', '16UC1', millimetres.tobytes(), 2 * width)):
                m = Image()
                m.header.stamp, m.header.frame_id, m.header.seq = stamp, c['optical'], q
                m.height, m.width, m.encoding, m.step, m.data = height, width, encoding, step, data
                pubs[name].publish(m)
            pubs['info'].publish(info)
            time.sleep(0.05)
        cls.stats = cls.wait_stats(lambda s: s.frames_offered + s.frames_dropped >= cls.frames and
                                   s.images_in_synchroniser == 0, 'every frame handled')
        cls.before = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection
        cls.after = cls.before
        if path_pub:
            path = Path()
            path.header.stamp, path.header.frame_id = rospy.Time.now(), world
            for stamp, (tb, qb) in cls.true_body:
                path.poses.append(pose_msg(tb, qb, stamp, world))
            path_pub.publish(path)
            cls.stats = cls.wait_stats(lambda s: s.paths_applied >= 1, 'the path applied')
            cls.after = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection

    @classmethod
    def wait_stats(cls, predicate, what):
        deadline, s = time.time() + cls.timeout, None
        while time.time() < deadline:
            s = rospy.wait_for_message(cls.node + '/statistics', InputStatistics, timeout=cls.timeout)
            if predicate(s):
                return s
            time.sleep(0.2)
        raise AssertionError('%s: not within %.0f s (last statistics: %s)' % (what, cls.timeout, s))

    def pose_errors(self, selection):
        truth = {msg_stamp_ns(t): p for t, p in self.truth}
        out = []
        for k in selection.keyframes:
            t, q = truth[msg_stamp_ns(k.stamp)]
            p = k.pose.position
            o = k.pose.orientation
            dot = abs(sum(a * b for a, b in zip((o.x, o.y, o.z, o.w), q)))
            out.append((math.sqrt((p.x - t[0]) ** 2 + (p.y - t[1]) ** 2 + (p.z - t[2]) ** 2),
                        2.0 * math.acos(min(1.0, dot))))
        return out

    def test_every_frame_arrives(self):
        s = self.stats
        self.assertEqual(s.frames_dropped, 0, '%s (last: %s)' % (dict(zip(s.drop_reasons, s.drop_counts)), s.last_error))
        self.assertEqual(s.images_arrived, self.frames)
        self.assertEqual(s.frames_received, self.frames)
        self.assertEqual(s.frames_offered, self.frames)
        self.assertGreaterEqual(len(self.after.keyframes), 5)

    def test_keyframe_poses_are_the_optical_frames(self):
        for i, (dp, da) in enumerate(self.pose_errors(self.after)):
            self.assertLess(dp, 1e-6, '%s keyframe %d is %.3g m off' % (self.name, i, dp))
            self.assertLess(da, 1e-6, '%s keyframe %d is %.3g rad off' % (self.name, i, da))

    def test_loop_closure_path(self):
        if not self.c['path']:
            self.skipTest('%s publishes no loop-closure path' % self.name)
        self.assertGreater(max(dp for dp, _ in self.pose_errors(self.before)), 0.02, 'the drift shows before the path')
        self.assertEqual(self.stats.paths_applied, 1)
        self.assertGreaterEqual(self.stats.keyframes_corrected, len(self.after.keyframes) - 1)


if __name__ == '__main__':
    rospy.init_node('slam_conventions_tester')
    rostest.rosrun(PKG, 'slam_conventions', SlamConventions, sys.argv)
