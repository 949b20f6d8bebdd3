#!/usr/bin/env python3
"""Loop-closure rostest (test/ros/corrections.test, corrections_keyframe_only.test): frames with
drifting poses of a body frame, then a nav_msgs/Path of the true trajectory; the node's final
selection must equal select_views's on the folder, whose poses are that true trajectory.

With a path pose at every frame stamp (~path_every 0, corrections.test) the tolerances are: keyframe
poses to 1e-9 (the path's pose composed with the extrinsic); E to 1e-6 relative (the points were
back-projected with the drifted pose and moved with the keyframe, so they equal the folder's to
rounding); next view sets, order, completion and pairs exactly.

With a keyframe-only path (~path_every N, as VINS' pose_graph_path and RTAB-Map's mapPath carry
only their own keyframes: one pose every N frames, ~path_shift seconds off the frame stamps, so
none shares a stamp with the node's keyframes) every keyframe takes the correction interpolated
at its stamp. Tolerances (KEYFRAME_ONLY_*): keyframe positions within 0.5 mm and 0.05 degrees of
the truth (the drift is 3 cm/s and 1.5 deg/s; the interpolation between path poses 0.23 s apart
leaves tens of micrometres), E within 1% relative, next view sets equal up to near-ties (a view
in one set and not the other is within 1% of the set's worst, by select_views's E), pairs at
least 95% shared.

With ~later_frames N (corrections_later_frames.test, ~correct_later_frames set on the node) the
odometry goes on drifting after the path, as VINS' does after loop_fusion closed a loop, for N more
frames. Each keyframe among them must lie where the path's last correction puts its drifted pose
(the drift since the path's last stamp only) to 1e-6 m and 1e-6 of a quaternion, and so not where
the source put it (off by the whole drift, centimetres).
"""
import json
import math
import os
import sys
import tempfile
import time
import unittest

import numpy
import rospy
import rostest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'replay'))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_poses import camera_info_msg, compose, inverse, pose_msg, slerp, transform_msg, yaw  # noqa: E402
from replay_tester import Replay  # noqa: E402
from vs_replay import msg_stamp_ns, remove_output, run, stamp_ns, tum_rows, wait_for_statistics  # noqa: E402
from vs_robust import find_tool  # noqa: E402

from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from view_selection.msg import ViewSelection  # noqa: E402
from view_selection.srv import GetSelection  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

PKG = 'view_selection'
KEYFRAME_ONLY_POSITION = 5e-4  # [m]
KEYFRAME_ONLY_ANGLE = 0.05     # [deg]
KEYFRAME_ONLY_E = 0.01         # relative
KEYFRAME_ONLY_PAIRS = 0.95     # shared
# camera_link (x forward, y left, z up) <- optical frame (z forward, x right, y down), 3 cm off.
EXTRINSIC_T = numpy.array([0.03, -0.01, 0.02])
EXTRINSIC_Q = numpy.array([-0.5, 0.5, -0.5, 0.5])  # x, y, z, w


def interpolate(a, b, s):
    return a[0] + s * (b[0] - a[0]), slerp(a[1], b[1], s)


def ros_time(stamp):
    ns = stamp_ns(stamp)
    return rospy.Time(ns // 1000000000, ns % 1000000000)


class Corrections(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.node = rospy.get_param('~node')
        cls.dataset = rospy.get_param('~dataset')
        cls.frames = int(rospy.get_param('~frames', 60))
        cls.path_every = int(rospy.get_param('~path_every', 0))
        cls.path_shift = float(rospy.get_param('~path_shift', 0.0))
        cls.later_frames = int(rospy.get_param('~later_frames', 0))
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
        remove_output(cls.tmp, 'corrections test')

    @classmethod
    def run_sequence(cls):
        import cv2
        total = cls.frames + cls.later_frames
        rgb, depth = tum_rows(cls.dataset, 'rgb.txt')[:total], tum_rows(cls.dataset, 'depth.txt')[:total]
        truth = {round(float(r[0]), 6): (numpy.array([float(x) for x in r[1:4]]),
                                         numpy.array([float(x) for x in r[4:8]])) for r in tum_rows(cls.dataset, 'groundtruth.txt')}
        with open(os.path.join(cls.dataset, 'camera.yaml')) as f:
            k = dict(line.split(':') for line in f if ':' in line and not line.startswith('#'))
        fx, fy, cx, cy = (float(k[n]) for n in ('fx', 'fy', 'cx', 'cy'))
        width, height = int(k['width']), int(k['height'])

        static = rospy.Publisher('/tf_static', TFMessage, queue_size=1, latch=True)
        t = transform_msg('camera_link', 'openni_rgb_optical_frame', EXTRINSIC_T, EXTRINSIC_Q, rospy.Time.now())
        static.publish(TFMessage(transforms=[t]))

        pubs = {n: rospy.Publisher('/drift/' + n, m, queue_size=100)
                for n, m in (('image', Image), ('camera_info', CameraInfo), ('depth', Image), ('pose', PoseStamped))}
        path_pub = rospy.Publisher('/drift/path', Path, queue_size=10, latch=True)
        cls.path_pub = path_pub
        deadline = time.time() + cls.timeout
        while time.time() < deadline and not all(p.get_num_connections() > 0 for p in pubs.values()):
            time.sleep(0.1)
        assert all(p.get_num_connections() > 0 for p in pubs.values()), 'the node did not subscribe'
        time.sleep(0.5)
        body_in_optical = inverse((EXTRINSIC_T, EXTRINSIC_Q))
        cls.true_body = []
        cls.t0 = float(rgb[0][0])

        def send(q, s, rgb_path, depth_path):
            stamp = ros_time(float(s))
            optical = truth[round(float(s), 6)]
            optical = (optical[0], optical[1] / numpy.linalg.norm(optical[1]))
            body = compose(optical, body_in_optical)
            cls.true_body.append((stamp, body))
            drifted = compose(cls.drift(float(s)), body)
            pubs['pose'].publish(pose_msg(drifted[0], drifted[1], stamp))
            info = camera_info_msg(stamp, 'openni_rgb_optical_frame', width, height, fx, fy, cx, cy)
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

        rows = list(enumerate(zip(rgb, depth)))
        for q, ((s, rgb_path), (_, depth_path)) in rows[:cls.frames]:
            send(q, s, rgb_path, depth_path)
        cls.wait_stats(lambda s: s.frames_offered + s.frames_dropped >= cls.frames and s.images_in_synchroniser == 0,
                       'every frame handled')
        cls.before = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection
        path = Path()
        path.header.stamp, path.header.frame_id = rospy.Time.now(), 'world'
        if cls.path_every == 0:
            for stamp, (tb, qb) in cls.true_body:
                path.poses.append(pose_msg(tb, qb, stamp))
        else:
            # The SLAM system's keyframes only, on stamps of its own: the truth between two frames.
            for q in range(0, len(cls.true_body) - 1, cls.path_every):
                (ta, a), (tb, b) = cls.true_body[q], cls.true_body[q + 1]
                s = cls.path_shift / (tb - ta).to_sec()
                t, r = interpolate(a, b, s)
                path.poses.append(pose_msg(t, r, ta + rospy.Duration.from_sec(cls.path_shift)))
        cls.path_poses = len(path.poses)
        cls.path_stamps = {msg_stamp_ns(p.header.stamp) for p in path.poses}
        path_pub.publish(path)
        # Applied: the corrected selection is shared before the path is counted.
        cls.stats = cls.wait_stats(lambda s: s.paths_applied >= 1, 'the path applied')
        cls.after = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection
        cls.later = None
        if cls.later_frames:
            # test_3 reads the selection published for the path: it must be out before more come.
            cls.wait_republished()
            cls.path_last = max(p.header.stamp for p in path.poses)
            for q, ((s, rgb_path), (_, depth_path)) in rows[cls.frames:]:
                send(q, s, rgb_path, depth_path)
            total = cls.frames + cls.later_frames
            cls.wait_stats(lambda s: s.frames_offered + s.frames_dropped >= total and s.images_in_synchroniser == 0,
                           'every later frame handled')
            cls.later = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection

    @classmethod
    def drift(cls, stamp):
        """The drift in the world at `stamp`: 3 cm/s and 1.5 deg/s, as odometry accumulates
        before a loop closes (and after it, for a source that is not corrected itself)."""
        dt = stamp - cls.t0
        return numpy.array([0.03 * dt, 0.0, -0.01 * dt]), yaw(math.radians(1.5 * dt))

    @classmethod
    def wait_republished(cls):
        """Waits for a ~selection whose last keyframe is at the corrected (the true) position."""
        x = cls.expected['keyframes'][-1]['position']
        deadline = time.time() + cls.timeout
        while time.time() < deadline and not cls.republished(x):
            time.sleep(0.1)

    @classmethod
    def republished(cls, x):
        return [m for m in list(cls.selections)
                if len(m.keyframes) == len(cls.expected['keyframes']) and
                abs(m.keyframes[-1].pose.position.x - x[0]) < 1e-3]

    @classmethod
    def wait_stats(cls, predicate, what):
        return wait_for_statistics(cls.node, predicate, cls.timeout, what)

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
        if self.path_every:
            return self.check_within_tolerances()
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

    def check_within_tolerances(self):
        s, e = self.after, self.expected
        self.assertLess(self.path_poses, self.frames / 4, 'a keyframe-only path has few poses')
        self.assertEqual([msg_stamp_ns(k.stamp) for k in s.keyframes], [stamp_ns(k['stamp']) for k in e['keyframes']])
        path_stamps = self.path_stamps
        worst_position = worst_angle = worst_e = 0.0
        for k, x in zip(s.keyframes, e['keyframes']):
            self.assertNotIn(msg_stamp_ns(k.stamp), path_stamps)
            p, q = k.pose.position, k.pose.orientation
            error = math.sqrt(sum((a - b) ** 2 for a, b in zip((p.x, p.y, p.z), x['position'])))
            dot = min(1.0, abs(sum(a * b for a, b in zip((q.x, q.y, q.z, q.w), x['orientation_xyzw']))))
            angle = math.degrees(2.0 * math.acos(dot))
            worst_position, worst_angle = max(worst_position, error), max(worst_angle, angle)
            self.assertLessEqual(error, KEYFRAME_ONLY_POSITION, 'keyframe %d: %.2e m from the truth' % (k.id, error))
            self.assertLessEqual(angle, KEYFRAME_ONLY_ANGLE, 'keyframe %d: %.3f deg from the truth' % (k.id, angle))
            self.assertEqual(k.num_points, x['num_points'])
        matrix = e['error_resistance']
        swapped = 0
        for i, v in enumerate(s.next_view_sets):
            mine, theirs = list(v.next_views), e['next_views'][i]
            for j, value in zip(v.next_views, v.error_resistance):
                self.assertIsNotNone(matrix[i][j], 'E[%d][%d] finite in the node only' % (i, j))
                relative = abs(value - matrix[i][j]) / matrix[i][j]
                worst_e = max(worst_e, relative)
                self.assertLessEqual(relative, KEYFRAME_ONLY_E, 'E[%d][%d] %r vs %r' % (i, j, value, matrix[i][j]))
            if mine != theirs:
                swapped += 1
                worst = max(matrix[i][j] for j in theirs) if theirs else 0.0
                for j in set(mine) ^ set(theirs):
                    self.assertIsNotNone(matrix[i][j])
                    self.assertLessEqual(matrix[i][j], worst * (1.0 + KEYFRAME_ONLY_E),
                                         'C_%d: %s vs select_views %s, and view %d is no near-tie' % (i, mine, theirs, j))
        mine = {(p.first, p.second) for p in s.pairs}
        theirs = {tuple(p) for p in e['pairs']}
        shared = len(mine & theirs) / float(max(len(mine | theirs), 1))
        rospy.loginfo('keyframe-only path of %d poses: keyframes within %.3f mm and %.4f deg of the truth, E within '
                      '%.2e, %d next view sets with a near-tie swapped, %.1f%% of pairs shared', self.path_poses,
                      1e3 * worst_position, worst_angle, worst_e, swapped, 100 * shared)
        self.assertGreaterEqual(shared, KEYFRAME_ONLY_PAIRS)

    def test_3_selection_was_republished(self):
        # Within ~publish_period (0.5 s by default) of the correction.
        x = self.expected['keyframes'][-1]['position']
        self.wait_republished()
        self.assertTrue(self.selections, 'no ~selection message')
        republished = self.republished(x)
        self.assertTrue(republished, 'no ~selection with the corrected keyframes')
        last = republished[-1]
        if self.path_every:
            self.assertAlmostEqual(last.keyframes[-1].pose.position.x, x[0], delta=KEYFRAME_ONLY_POSITION)
            return
        self.assertEqual([[p.first, p.second] for p in last.pairs], self.expected['pairs'])
        self.assertAlmostEqual(last.keyframes[-1].pose.position.x, x[0], delta=1e-9)

    def test_5_paths_that_correct_nothing(self):
        # A path that ends just before the node's first frame (a SLAM system's first paths) is
        # nothing to correct yet: no drop. One of another session (its stamps far from every
        # frame) and one in another frame are wrong: each is a bad_path drop. None moves a keyframe.
        def bad_paths(s):
            return dict(zip(s.drop_reasons, s.drop_counts)).get('bad_path', 0)

        before = self.wait_stats(lambda s: True, 'the statistics')
        kept = rospy.ServiceProxy(self.node + '/get_selection', GetSelection)().selection
        first = self.true_body[0][0]

        def path(shift, frame='world'):
            p = Path()
            p.header.stamp, p.header.frame_id = rospy.Time.now(), frame
            for stamp, (t, q) in self.true_body[:10]:
                p.poses.append(pose_msg(t + 0.5, q, stamp + rospy.Duration.from_sec(shift), frame))
            return p

        span = (self.true_body[9][0] - first).to_sec()
        self.path_pub.publish(path(1000.0))        # another session
        self.wait_stats(lambda s: bad_paths(s) >= bad_paths(before) + 1, 'the path of another session dropped')
        self.path_pub.publish(path(-span - 1.0))   # ends 1 s before the first frame
        self.path_pub.publish(path(0.0, 'map'))    # another frame, taken after the one before
        after = self.wait_stats(lambda s: "'map'" in s.last_error, 'the path in map dropped')
        self.assertEqual(bad_paths(after), bad_paths(before) + 2, after.last_error)
        self.assertEqual(after.paths_applied, before.paths_applied)
        self.assertEqual(after.keyframes_corrected, before.keyframes_corrected)
        now = rospy.ServiceProxy(self.node + '/get_selection', GetSelection)().selection
        self.assertEqual([(k.pose.position.x, k.pose.position.y, k.pose.position.z) for k in now.keyframes],
                         [(k.pose.position.x, k.pose.position.y, k.pose.position.z) for k in kept.keyframes])


class LaterFrames(Corrections):
    """Corrections' tests, and the frames after the path (~later_frames > 0)."""

    def test_4_later_frames_take_the_last_correction(self):
        self.assertIsNotNone(self.later)
        before = len(self.after.keyframes)
        later = self.later.keyframes[before:]
        self.assertEqual([msg_stamp_ns(k.stamp) for k in self.later.keyframes[:before]],
                         [msg_stamp_ns(k.stamp) for k in self.after.keyframes])
        self.assertGreaterEqual(len(later), self.later_frames // 5 - 1, 'keyframes every 5th frame')
        # The path's last correction: its pose times the source's pose there, inverted. The path
        # is the truth, so the correction is the drift at the path's last stamp, undone.
        undo = inverse(self.drift(self.path_last.to_sec()))
        truth = {msg_stamp_ns(stamp): body for stamp, body in self.true_body}
        extrinsic = (EXTRINSIC_T, EXTRINSIC_Q)
        worst = 0.0
        for k in later:
            self.assertGreater(k.stamp, self.path_last)
            body = truth[msg_stamp_ns(k.stamp)]
            source = compose(compose(self.drift(k.stamp.to_sec()), body), extrinsic)
            expected = compose(undo, source)
            p, q = k.pose.position, k.pose.orientation
            position = numpy.array([p.x, p.y, p.z])
            self.assertLess(numpy.linalg.norm(position - expected[0]), 1e-6, 'keyframe %d' % k.id)
            dot = abs(float(numpy.dot([q.x, q.y, q.z, q.w], expected[1])))
            self.assertGreater(dot, 1.0 - 1e-6, 'keyframe %d' % k.id)
            worst = max(worst, numpy.linalg.norm(position - source[0]))
        # What the source alone would have given is off by the drift before the path's end.
        self.assertGreater(worst, 0.02, 'the correction should have moved the later keyframes by centimetres')


if __name__ == '__main__':
    rospy.init_node('corrections_tester')
    rostest.rosrun(PKG, 'corrections', LaterFrames if rospy.get_param('~later_frames', 0) else Corrections, sys.argv)
