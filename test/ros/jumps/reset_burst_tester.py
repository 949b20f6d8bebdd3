#!/usr/bin/env python3
"""~reset in the middle of a burst (test/ros/reset_burst.test). A node with poses on a topic and
external keyframes (otherwise the shipped parameters) gets

  1. frames 0-4 and a keyframe path naming frames 0, 2, 4, 6, 8 and 11 (the old session's verdicts);
  2. the images of frames 5-9 alone: they wait in the synchroniser for their camera_info and depth;
  3. ~reset, while they wait;
  4. the camera_info and depth of frames 5-9 (which would release them), a new keyframe path
     naming frames 10, 12 and 14, and frames 10-14.

The new session must hold exactly frames 10-14: none of 5-9 received, offered or dropped, and the
keyframes exactly 10, 12 and 14 (frame 11 is no keyframe: the old path's verdict for it is gone).
"""
import os
import sys
import unittest

import rospy
import rostest
import yaml
from nav_msgs.msg import Path
from std_srvs.srv import Trigger

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_robust import (FramePublisher, NodeProcess, Statistics, call, synthetic_frames,  # noqa: E402
                       wait_until)

from view_selection.srv import GetSelection  # noqa: E402

PKG = 'view_selection'
TIMEOUT = 30.0
OLD_KEYFRAMES, NEW_KEYFRAMES = (0, 2, 4, 6, 8, 11), (10, 12, 14)


def stamp_key(t):
    return (t.secs, t.nsecs)


class ResetBurst(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        with open(rospy.get_param('~config')) as f:
            params = yaml.safe_load(f)
        params.update(pose_source='topic', keyframe_policy='external')
        cls.publisher = FramePublisher('/burst/camera')
        remaps = cls.publisher.remaps()
        remaps['keyframes'] = '/burst/keyframes'
        cls.keyframes = rospy.Publisher('/burst/keyframes', Path, queue_size=10, latch=True)
        cls.node = NodeProcess('burst_view_selection', params, remaps=remaps).start()
        cls.stats = Statistics(cls.node.name)
        cls.result = None
        try:
            cls.node.wait_for_services(TIMEOUT)
            cls.publisher.wait_connected(TIMEOUT)
            wait_until(lambda: cls.keyframes.get_num_connections() > 0, TIMEOUT, 'subscriber on /burst/keyframes')
            cls.frames = synthetic_frames(15)
            cls.run_burst()
        except Exception:
            rospy.logerr('node output:\n%s', cls.node.output()[-4000:])
            raise

    @classmethod
    def tearDownClass(cls):
        cls.stats.close()
        cls.node.stop()
        cls.publisher.close()

    @classmethod
    def path(cls, indices):
        path = Path()
        path.header.frame_id = 'world'
        path.header.stamp = cls.frames[indices[-1]].stamp
        path.poses = [cls.frames[i].pose for i in indices]
        return path

    @classmethod
    def publish_in_order(cls, frames):
        """Each frame once the node has received the one before (its images queue in order)."""
        for f in frames:
            before = cls.stats.get().frames_received if cls.stats.get() else 0
            cls.publisher.publish(f)
            cls.stats.wait(lambda s: s.frames_received > before, TIMEOUT, 'receives the frame at %s' % f.stamp)

    @classmethod
    def run_burst(cls):
        frames, pub = cls.frames, cls.publisher
        # Latched, and the worker waits (~keyframe_verdict_timeout) for a verdict it lacks.
        cls.keyframes.publish(cls.path(OLD_KEYFRAMES))
        cls.publish_in_order(frames[:5])
        cls.stats.wait(lambda s: s.frames_offered == 5 and s.images_in_synchroniser == 0, TIMEOUT,
                       'offers frames 0-4')
        # The images of 5-9 (and their poses) without their partners: they wait (~sync_timeout 1 s,
        # counted from the last message of their partners' inputs).
        for f in frames[5:10]:
            pub.publish_pose(f)
            pub.image.publish(f.image)
        cls.stats.wait(lambda s: s.images_arrived == 10 and s.images_in_synchroniser == 5, TIMEOUT,
                       'holds the images of frames 5-9 in the synchroniser')
        answer = call(cls.node.name + '/reset', Trigger, timeout=TIMEOUT)
        assert answer.success, answer.message
        for f in frames[5:10]:  # the partners that would release them
            pub.depth.publish(f.depth)
            pub.info.publish(f.info)
        cls.stats.wait(lambda s: s.depths_arrived == 5 and s.camera_infos_arrived == 5, TIMEOUT,
                       'receives the partners of frames 5-9 after the reset')
        cls.keyframes.publish(cls.path(NEW_KEYFRAMES))
        cls.publish_in_order(frames[10:])
        # Frames are handled in order, after anything released before them: once 10-14 are handled
        # and nothing waits, the session is complete.
        cls.result = cls.stats.wait(lambda s: s.frames_offered + s.frames_dropped >= 5 and
                                    s.images_in_synchroniser == 0, TIMEOUT, 'handles frames 10-14')
        cls.selection = call(cls.node.name + '/get_selection', GetSelection, timeout=TIMEOUT).selection

    def test_waiting_images_do_not_enter_the_new_session(self):
        s = self.result
        drops = dict(zip(s.drop_reasons, s.drop_counts))
        self.assertEqual(drops, {}, 'drops in the new session: %s' % s.last_error)
        self.assertEqual((s.frames_received, s.frames_offered), (5, 5),
                         'frames received and offered in the new session: only 10-14')
        self.assertEqual((s.images_arrived, s.images_in_synchroniser), (5, 0))

    def test_old_verdicts_do_not_enter_the_new_session(self):
        stamps = [stamp_key(k.stamp) for k in self.selection.keyframes]
        self.assertEqual(stamps, [stamp_key(self.frames[i].stamp) for i in NEW_KEYFRAMES],
                         'keyframes of the new session (frames %s expected)' % (NEW_KEYFRAMES,))


if __name__ == '__main__':
    rospy.init_node('reset_burst_tester')
    rostest.rosrun(PKG, 'reset_burst', ResetBurst, sys.argv)
