#!/usr/bin/env python3
"""Time-jump rostest (test/ros/time_jumps.test): the bag of replay.test played twice into the
same nodes, as a user plays a bag again. After the second play each node must have started a new
session at the jump (~statistics time_jumps 1), handled every frame of the second play (none
dropped, out_of_order_stamp included), and hold the selection select_views gives on the same
frames: replay.test's checks, on the second play's session.
"""
import os
import sys
import time

import rospy
import rostest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'replay'))
from replay_tester import Replay  # noqa: E402

from rosgraph_msgs.msg import Log  # noqa: E402
from view_selection.msg import InputStatistics  # noqa: E402

PKG = 'view_selection'


class TimeJumps(Replay):
    # The bag's layout and tum_to_bag's errors are replay.test's; here only the nodes.
    test_2_bag_has_the_tum_layout = None
    test_3_tum_to_bag_reports_bad_input = None

    @classmethod
    def play(cls):
        """Two plays of the same bag; the first one's session is checked in passing."""
        cls.plays = 0
        cls.warnings = {node: [] for node in cls.nodes}

        def on_log(m):
            if m.name in cls.warnings and m.level == Log.WARN and 'time jumped back' in m.msg:
                cls.warnings[m.name].append(m.msg)
        cls.log_sub = rospy.Subscriber('/rosout', Log, on_log, queue_size=1000)
        super(TimeJumps, cls).play()
        cls.plays = 1
        cls.wait_until_processed()
        cls.first = {node: rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=cls.timeout)
                     for node in cls.nodes}
        super(TimeJumps, cls).play()
        cls.plays = 2

    @classmethod
    def wait_until_processed(cls):
        """Until each node counted the jumps so far and handled every frame after the last."""
        for node in cls.nodes:
            deadline = time.time() + cls.timeout
            while True:
                stats = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=cls.timeout)
                if (stats.time_jumps >= cls.plays - 1 and
                        stats.frames_offered + stats.frames_dropped >= cls.frames):
                    break
                if time.time() > deadline:
                    rospy.logwarn('%s: %d time jumps, handled %d of %d frames within %.0f s', node,
                                  stats.time_jumps, stats.frames_offered + stats.frames_dropped,
                                  cls.frames, cls.timeout)
                    break  # the checks say what is missing
                time.sleep(0.1)

    def _check_node(self, index):
        if index >= len(self.nodes):
            self.skipTest('no node %d in ~nodes' % index)
        node, tolerance = self.nodes[index], self.tolerances[index]
        first = self.first[node]
        self.assertEqual((first.time_jumps, first.frames_offered, first.frames_dropped), (0, self.frames, 0),
                         node + ': the first play (time jumps, frames offered, dropped): %s' % first.last_error)
        stats = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=self.timeout)
        self.assertEqual(stats.time_jumps, 1, node + ': time jumps')
        # Logged once, with the newest stamp of the first play and the first of the second.
        stamps = sorted(k['stamp'] for k in self.expected['keyframes'])
        warnings = self.warnings[node]
        self.assertEqual(len(warnings), 1, node + ': time-jump warnings: %s' % warnings)
        self.assertIn(' to %.6f ' % stamps[0], warnings[0])
        # The second play's frames, each offered (none an out_of_order_stamp), its keyframes only.
        self.check_statistics(node)
        self.assertEqual(stats.images_arrived, self.frames, node + ': images of the second play')
        self.check_selection(node, tolerance)
        self.check_export(node)


if __name__ == '__main__':
    rospy.init_node('time_jumps_tester')
    rostest.rosrun(PKG, 'time_jumps', TimeJumps, sys.argv)
