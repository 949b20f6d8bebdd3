#!/usr/bin/env python3
"""SLAM-system rostests (test/ros/slam_*.test): the package's launch file for one SLAM system, at
its own defaults, next to stand-ins that run under the real system's node names and publish its
topics, types, frames, clocks and conventions (slam_stand_in.py; ORB-SLAM2: PoseStamped in map
of x-forward camera_link; ORB-SLAM3: PoseStamped of the optical frame; RTAB-Map: tf map -> odom ->
base_link, mapPath of its 1 Hz map nodes; VINS-Fusion: Odometry of the IMU body at 15 Hz on a clock
of its own, pose_graph_path of its keyframes). This tester is the camera driver and the robot
description: images, camera_info, depth (16UC1) and the fixed chain; it sends each frame's true
pose to the stand-ins before the frame's image. The frames are the built-in synthetic sequence
(generate_sequence: exact poses), so no data folder is needed; the first and last LEAD frames are
tracked by the stand-ins but have no image (odometry on another clock starts before the first).

Checks: the node and every stand-in are up at the end under their own names (a clash would have
stopped roslaunch, or the master would have killed one); every image reaches the node and none is
dropped, for want of a pose or anything else; each keyframe's pose is the optical frame's true pose
once the body-frame conventions are undone (1e-6 m and rad for the systems that publish poses at
the frame stamps and need no correction); for the
systems with a loop-closure path, poses drift first (the keyframes are off by centimetres) and the
keyframe-only path brings every keyframe back to the truth: within PATH_POSITION / PATH_ANGLE
between the path poses the node had frames at, and outside them (VINS' keyframes on its own clock:
the first one during the images may come 0.27 s after the first image) within what the drift
moved since the nearest of them, which is the correction those keyframes take.

After the loop closure the camera goes on for ~later_frames more frames (the first of them LEAD
frames after the last image, the last LEAD of them without images again) and the odometry goes on
drifting: every keyframe among them must be within what the drift moved since the path's last
pose the node had frames at, as the nearest correction above; RTAB-Map's poses come corrected by
its map -> odom, VINS' odometry does not (vins_fusion.launch sets ~correct_later_frames). RTAB-Map's
mapPath goes on growing with the later frames' map nodes: measured against the map poses, the
keyframes between the loop's node and the next would take part of the loop's correction a second
time (0.22 m; rtabmap.launch sets ~odom_frame). Uncorrected,
they would be off by the whole drift (centimetres more); the systems without a path, exact.
"""
import math
import os
import sys
import tempfile
import time
import unittest

import numpy
import rosgraph
import rospy
import rostest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
import slam_systems as systems  # noqa: E402
from slam_systems import CONVENTIONS, compose  # noqa: E402
from vs_poses import camera_info_msg, pose_msg, transform_msg as transform  # noqa: E402
from vs_replay import msg_stamp_ns, remove_output, run, stamp_ns, tum_rows, wait_for_statistics  # noqa: E402
from vs_robust import find_tool  # noqa: E402

from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from std_msgs.msg import Empty  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402
from view_selection.srv import GetSelection  # noqa: E402

PKG = 'view_selection'
LEAD = 4                 # frames at each end with a true pose but no image
# After a keyframe-only path, between its poses (measured: RTAB-Map 0.47 mm and 0 deg; VINS, whose
# 15 Hz odometry on its own clock is interpolated twice, by the stand-in and the node, 1.45 mm
# and 0.12 deg).
PATH_POSITION = 3e-3     # [m]
PATH_ANGLE = 0.3         # [deg]


class SlamConventions(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.name = rospy.get_param('~convention')
        cls.c = CONVENTIONS[cls.name]
        cls.node = rospy.get_param('~node', cls.c['ours'])
        cls.frames = int(rospy.get_param('~frames', 96))
        cls.later_frames = int(rospy.get_param('~later_frames', 36))
        cls.images = cls.frames - 2 * LEAD + cls.later_frames - LEAD
        cls.timeout = float(rospy.get_param('~timeout', 60.0))
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_slam_')
        generate = find_tool('generate_sequence')
        if not generate:
            raise AssertionError('generate_sequence is not built')
        cls.folder = os.path.join(cls.tmp, 'sequence')
        run([generate, '--out', cls.folder, '--frames', str(cls.frames + cls.later_frames), '--quiet'], 600,
            'generate_sequence')
        cls.run_sequence()

    @classmethod
    def tearDownClass(cls):
        remove_output(cls.tmp, 'slam test')

    @classmethod
    def wait_for(cls, publishers, what):
        deadline = time.time() + cls.timeout
        while time.time() < deadline and not all(p.get_num_connections() >= n for p, n in publishers):
            time.sleep(0.1)
        assert all(p.get_num_connections() >= n for p, n in publishers), what

    @classmethod
    def run_sequence(cls):
        import cv2
        c = cls.c
        rgb, depth, truth = (tum_rows(cls.folder, name) for name in ('rgb.txt', 'depth.txt', 'groundtruth.txt'))
        with open(os.path.join(cls.folder, 'camera.yaml')) as f:
            k = dict(line.split(':') for line in f if ':' in line and not line.startswith('#'))
        fx, fy, cx, cy = (float(k[n]) for n in ('fx', 'fy', 'cx', 'cy'))
        width, height = int(k['width']), int(k['height'])
        to_body = systems.body_in_optical(c)

        tf_static = rospy.Publisher('/tf_static', TFMessage, queue_size=1, latch=True)
        if c['chain']:
            tf_static.publish(TFMessage(transforms=[transform(p, ch, t, q, rospy.Time.now())
                                                    for p, ch, t, q in c['chain']]))
        pubs = {'image': rospy.Publisher(c['image'], Image, queue_size=100),
                'info': rospy.Publisher(c['info'], CameraInfo, queue_size=100),
                'depth': rospy.Publisher(c['depth'], Image, queue_size=100)}
        truth_pub = rospy.Publisher(systems.TRUTH_TOPIC, PoseStamped, queue_size=1000)
        close_loop = rospy.Publisher(systems.CLOSE_LOOP_TOPIC, Empty, queue_size=1, latch=False)
        cls.wait_for([(p, 1) for p in pubs.values()], 'the node did not subscribe to the camera')
        cls.wait_for([(truth_pub, len(c['stand_ins']))], 'the stand-ins did not subscribe to the truth')
        if c['path']:
            cls.wait_for([(close_loop, sum(1 for _, role in c['stand_ins'] if role in ('rtabmap', 'loop_fusion')))],
                         'the stand-in with the path did not subscribe')
        cls.wait_for_pose_stream()
        time.sleep(0.5)

        def send(q, s, rgb_path, depth_path, row, image):
            """The frame's true pose to the stand-ins, then (with `image`) its image, depth and
            camera info to the node; at the camera's rate."""
            stamp = rospy.Time(int(stamp_ns(float(s)) // 1000000000), int(stamp_ns(float(s)) % 1000000000))
            optical = (numpy.array([float(x) for x in row[1:4]]), numpy.array([float(x) for x in row[4:8]]))
            optical = (optical[0], optical[1] / numpy.linalg.norm(optical[1]))
            cls.truth.append((stamp, optical))
            cls.true_body.append((stamp, compose(optical, to_body)))
            truth_pub.publish(pose_msg(optical[0], optical[1], stamp, 'truth'))
            if image:
                info = camera_info_msg(stamp, c['optical'], width, height, fx, fy, cx, cy)
                bgr = cv2.imread(os.path.join(cls.folder, rgb_path), cv2.IMREAD_COLOR)
                png = cv2.imread(os.path.join(cls.folder, depth_path), cv2.IMREAD_ANYDEPTH)
                millimetres = numpy.round(png.astype(numpy.float64) / 5.0).astype(numpy.uint16)  # 16UC1, as drivers
                for name, encoding, data, step in (('image', 'rgb8', bgr[:, :, ::-1].tobytes(), 3 * width),
                                                   ('depth', '16UC1', millimetres.tobytes(), 2 * width)):
                    m = Image()
                    m.header.stamp, m.header.frame_id, m.header.seq = stamp, c['optical'], q
                    m.height, m.width, m.encoding, m.step, m.data = height, width, encoding, step, data
                    pubs[name].publish(m)
                pubs['info'].publish(info)
            time.sleep(1.0 / 30.0)  # the camera's rate

        cls.truth, cls.true_body = [], []
        rows = list(enumerate(zip(rgb, depth, truth)))
        # Images but for LEAD frames at each end of the part before the loop closure and at the end.
        with_image = [LEAD <= q < cls.frames - LEAD or cls.frames <= q < len(rows) - LEAD for q, _ in rows]
        for q, ((s, rgb_path), (_, depth_path), row) in rows[:cls.frames]:
            send(q, s, rgb_path, depth_path, row, with_image[q])
        first = cls.frames - 2 * LEAD
        cls.stats = cls.wait_stats(lambda s: s.frames_offered + s.frames_dropped >= first and
                                   s.images_in_synchroniser == 0, 'every frame handled')
        cls.before = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection
        cls.after = cls.before
        if c['path']:
            cls.paths = []
            rospy.Subscriber(c['path'], Path, cls.paths.append)
            # VINS' path came with its keyframes already (its drifting poses: nothing to correct);
            # the loop's is the one that corrects every keyframe.
            before = cls.stats
            close_loop.publish(Empty())
            cls.stats = cls.wait_stats(
                lambda s: s.paths_applied > before.paths_applied and
                s.keyframes_corrected - before.keyframes_corrected >= len(cls.before.keyframes) - 1,
                "the loop's path applied")
            cls.loop_corrected = cls.stats.keyframes_corrected - before.keyframes_corrected
            cls.paths_before_loop = before.paths_applied
            cls.corrected_before_loop = before.keyframes_corrected
            cls.after = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection
        for q, ((s, rgb_path), (_, depth_path), row) in rows[cls.frames:]:
            send(q, s, rgb_path, depth_path, row, with_image[q])
        cls.stats = cls.wait_stats(lambda s: s.frames_offered + s.frames_dropped >= cls.images and
                                   s.images_in_synchroniser == 0, 'every later frame handled')
        cls.later = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection

    @classmethod
    def wait_for_pose_stream(cls):
        """The node listens to the stand-in's pose topic (or /tf)."""
        topic = cls.c['pose'][0]
        topic = '/tf' if topic == 'tf' else topic
        master = rosgraph.Master(rospy.get_name())
        deadline = time.time() + cls.timeout
        while time.time() < deadline:
            subscribers = {t: set(n) for t, n in master.getSystemState()[1]}
            if cls.node in subscribers.get(topic, ()):
                return
            time.sleep(0.1)
        raise AssertionError('%s does not subscribe to %s' % (cls.node, topic))

    @classmethod
    def wait_stats(cls, predicate, what):
        return wait_for_statistics(cls.node, predicate, cls.timeout, what)

    def pose_errors(self, keyframes):
        truth = {msg_stamp_ns(t): p for t, p in self.truth}
        out = []
        for k in keyframes:
            t, q = truth[msg_stamp_ns(k.stamp)]
            p = k.pose.position
            o = k.pose.orientation
            dot = abs(sum(a * b for a, b in zip((o.x, o.y, o.z, o.w), q)))
            out.append((math.sqrt((p.x - t[0]) ** 2 + (p.y - t[1]) ** 2 + (p.z - t[2]) ** 2),
                        math.degrees(2.0 * math.acos(min(1.0, dot)))))
        return out

    def test_names_do_not_clash(self):
        master = rosgraph.Master(rospy.get_name())
        names = [self.node] + [n for n, _ in self.c['stand_ins']]
        self.assertEqual(len(set(names)), len(names), names)
        for name in names:
            try:
                master.lookupNode(name)
            except Exception as e:
                self.fail('%s is not running at the end: %s' % (name, e))

    def test_every_frame_arrives(self):
        s = self.stats
        self.assertEqual(s.frames_dropped, 0, '%s (last: %s)' % (dict(zip(s.drop_reasons, s.drop_counts)), s.last_error))
        self.assertEqual(s.images_arrived, self.images)
        self.assertEqual(s.frames_received, self.images)
        self.assertEqual(s.frames_offered, self.images)
        self.assertGreaterEqual(len(self.after.keyframes), 8)

    def tolerances(self, keyframes):
        """(position [m], angle [deg]) allowed for each of `keyframes` after the path."""
        if not self.c['path']:
            return [(1e-6, math.degrees(1e-6))] * len(keyframes)
        images = [t.to_sec() for t, _ in self.truth[LEAD:self.frames - LEAD]]  # before the loop closure
        self.assertTrue(self.paths, 'the path was not received by the tester')
        usable = [p.header.stamp.to_sec() for p in self.paths[-1].poses
                  if images[0] <= p.header.stamp.to_sec() <= images[-1]]
        self.assertTrue(usable)
        truth = {msg_stamp_ns(t): p for t, p in self.truth}
        out = []
        for k in keyframes:
            t = k.stamp.to_sec()
            if usable[0] <= t <= usable[-1]:
                out.append((PATH_POSITION, PATH_ANGLE))
                continue
            # The nearest correction: the drift since then, 4.5 cm/s and 2 deg/s about the origin.
            dt = min(abs(t - usable[0]), abs(t - usable[-1]))
            radius = numpy.linalg.norm(truth[msg_stamp_ns(k.stamp)][0])
            out.append((PATH_POSITION + (0.045 + math.radians(2.0) * radius) * dt, PATH_ANGLE + 2.0 * dt))
        return out

    def test_keyframe_poses_are_the_optical_frames(self):
        errors = self.pose_errors(self.after.keyframes)
        tolerances = self.tolerances(self.after.keyframes)
        tight = [e for e, t in zip(errors, tolerances) if t == min(tolerances)]
        rospy.loginfo('%s: %d keyframes within %.3g m and %.3g deg of the truth; the %d between path poses within '
                      '%.3g m and %.3g deg', self.name, len(errors), max(dp for dp, _ in errors),
                      max(da for _, da in errors), len(tight), max(dp for dp, _ in tight), max(da for _, da in tight))
        for i, ((dp, da), (position, angle)) in enumerate(zip(errors, tolerances)):
            self.assertLess(dp, position, '%s keyframe %d is %.3g m off' % (self.name, i, dp))
            self.assertLess(da, angle, '%s keyframe %d is %.3g deg off' % (self.name, i, da))

    def test_frames_after_the_loop_closure(self):
        n = len(self.after.keyframes)
        self.assertEqual([msg_stamp_ns(k.stamp) for k in self.later.keyframes[:n]],
                         [msg_stamp_ns(k.stamp) for k in self.after.keyframes])
        later = self.later.keyframes[n:]
        self.assertGreaterEqual(len(later), 2, 'keyframes after the loop closure')
        last_image = self.truth[self.frames - LEAD - 1][0]
        errors, tolerances = self.pose_errors(later), self.tolerances(later)
        rospy.loginfo('%s: the %d keyframes after the loop closure within %.3g m and %.3g deg of the truth',
                      self.name, len(later), max(dp for dp, _ in errors), max(da for _, da in errors))
        for k, (dp, da), (position, angle) in zip(later, errors, tolerances):
            self.assertGreater(k.stamp, last_image)
            self.assertLess(dp, position, '%s keyframe %d after the loop closure is %.3g m off' % (self.name, k.id, dp))
            self.assertLess(da, angle, '%s keyframe %d after the loop closure is %.3g deg off' % (self.name, k.id, da))

    def test_loop_closure_path(self):
        if not self.c['path']:
            self.skipTest('%s publishes no loop-closure path' % self.name)
        self.assertGreater(max(dp for dp, _ in self.pose_errors(self.before.keyframes)), 0.02,
                           'the drift shows before the path')
        self.assertGreaterEqual(self.loop_corrected, len(self.after.keyframes) - 1)
        if self.name == 'vins_fusion':
            # loop_fusion's path as it grew, at the VIO's own poses: taken, and nothing moved by it
            # beyond the node's thresholds but for the odometry's interpolation (15 Hz, another clock).
            self.assertGreater(self.paths_before_loop, 5)
            self.assertLessEqual(self.corrected_before_loop, 2)
        elif self.name == 'rtabmap':
            # mapPath as the map grew, at the odometry's poses (map -> odom still the identity):
            # taken, and nothing moved by it.
            self.assertGreaterEqual(self.paths_before_loop, 1)
            self.assertEqual(self.corrected_before_loop, 0)
        else:
            self.assertEqual(self.paths_before_loop, 0)


if __name__ == '__main__':
    rospy.init_node('slam_conventions_tester')
    rostest.rosrun(PKG, 'slam_conventions', SlamConventions, sys.argv)
