#!/usr/bin/env python3
"""~keyframe_policy external (test/ros/external_keyframes.test): the built-in sequence's frames
with poses of the optical frame, and a growing nav_msgs/Path on /slam/keyframes with the stamps
of every third frame up to frame 30, as a SLAM system publishes its keyframes. The node's
keyframes must be exactly those frames; the frames after the last keyframe stamp never get a
verdict and must be counted as no_keyframe_verdict.
"""
import os
import shutil
import sys
import tempfile
import time
import unittest

import numpy
import rospy
import rostest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_poses import pose_msg  # noqa: E402
from vs_replay import msg_stamp_ns, run, stamp_ns  # noqa: E402
from vs_robust import find_tool  # noqa: E402

from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from sensor_msgs.msg import CameraInfo, Image  # noqa: E402
from view_selection.msg import InputStatistics  # noqa: E402
from view_selection.srv import GetSelection  # noqa: E402

PKG = 'view_selection'
FRAMES, EVERY, LAST_KEYFRAME = 40, 3, 30


class ExternalKeyframes(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        import cv2
        cls.node = rospy.get_param('~node')
        cls.timeout = float(rospy.get_param('~timeout', 60.0))
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_external_')
        folder = os.path.join(cls.tmp, 'sequence')
        run([find_tool('generate_sequence'), '--out', folder, '--frames', str(FRAMES), '--quiet'], 600,
            'generate_sequence')

        def rows(name):
            with open(os.path.join(folder, name)) as f:
                return [line.split() for line in f if line.strip() and not line.startswith('#')]
        with open(os.path.join(folder, 'camera.yaml')) as f:
            k = dict(line.split(':') for line in f if ':' in line and not line.startswith('#'))
        fx, fy, cx, cy = (float(k[n]) for n in ('fx', 'fy', 'cx', 'cy'))
        width, height = int(k['width']), int(k['height'])
        pubs = {n: rospy.Publisher('/slam/' + n, m, queue_size=100)
                for n, m in (('image', Image), ('camera_info', CameraInfo), ('depth', Image), ('pose', PoseStamped))}
        keyframes = rospy.Publisher('/slam/keyframes', Path, queue_size=10)
        waiting = list(pubs.values()) + [keyframes]
        deadline = time.time() + cls.timeout
        while time.time() < deadline and not all(p.get_num_connections() > 0 for p in waiting):
            time.sleep(0.1)
        assert all(p.get_num_connections() > 0 for p in waiting), 'the node did not subscribe'
        time.sleep(0.5)
        path = Path()
        path.header.frame_id = 'world'
        cls.expected = []
        for q, ((s, rgb), (_, dep), row) in enumerate(zip(rows('rgb.txt'), rows('depth.txt'), rows('groundtruth.txt'))):
            ns = stamp_ns(float(s))
            stamp = rospy.Time(ns // 1000000000, ns % 1000000000)
            t = numpy.array([float(x) for x in row[1:4]])
            qn = numpy.array([float(x) for x in row[4:8]])
            pubs['pose'].publish(pose_msg(t, qn / numpy.linalg.norm(qn), stamp))
            info = CameraInfo()
            info.header.stamp, info.header.frame_id = stamp, 'camera'
            info.width, info.height, info.distortion_model, info.D = width, height, 'plumb_bob', [0.0] * 5
            info.K = [fx, 0, cx, 0, fy, cy, 0, 0, 1]
            bgr = cv2.imread(os.path.join(folder, rgb), cv2.IMREAD_COLOR)
            png = cv2.imread(os.path.join(folder, dep), cv2.IMREAD_ANYDEPTH)
            metres = (png * (1.0 / 5000.0)).astype(numpy.float32)
            for name, encoding, data, step in (('image', 'bgr8', bgr.tobytes(), 3 * width),
                                               ('depth', '32FC1', metres.tobytes(), 4 * width)):
                m = Image()
                m.header.stamp, m.header.frame_id, m.header.seq = stamp, 'camera', q
                m.height, m.width, m.encoding, m.step, m.data = height, width, encoding, step, data
                pubs[name].publish(m)
            pubs['camera_info'].publish(info)
            if q % EVERY == 0 and q <= LAST_KEYFRAME:  # the SLAM system decides a little later
                cls.expected.append(ns)
                path.header.stamp = stamp
                path.poses.append(pose_msg(t, qn, stamp))
                keyframes.publish(path)
            time.sleep(0.05)
        deadline = time.time() + cls.timeout
        while time.time() < deadline:
            cls.stats = rospy.wait_for_message(cls.node + '/statistics', InputStatistics, timeout=cls.timeout)
            if cls.stats.frames_offered + cls.stats.frames_dropped >= FRAMES:
                break
            time.sleep(0.2)
        cls.selection = rospy.ServiceProxy(cls.node + '/get_selection', GetSelection)().selection

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    def test_keyframes_are_the_slam_systems(self):
        self.assertEqual([msg_stamp_ns(k.stamp) for k in self.selection.keyframes], self.expected)

    def test_frames_without_a_verdict_are_counted(self):
        drops = dict(zip(self.stats.drop_reasons, self.stats.drop_counts))
        self.assertEqual(drops, {'no_keyframe_verdict': FRAMES - 1 - LAST_KEYFRAME})
        self.assertEqual(self.stats.frames_offered, LAST_KEYFRAME + 1)
        self.assertEqual(self.stats.images_arrived, FRAMES)


if __name__ == '__main__':
    rospy.init_node('external_keyframes_tester')
    rostest.rosrun(PKG, 'external_keyframes', ExternalKeyframes, sys.argv)
