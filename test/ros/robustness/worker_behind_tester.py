#!/usr/bin/env python3
"""Nothing waits for the worker: a node whose point source takes 200 ms a keyframe more than the
real one, and 4 s for one keyframe (slow_points_node), gets a 30 Hz burst of 300 frames, every
one a keyframe, at the node's shipped defaults (~max_pending_frames 30, ~subscriber_queue_size 100). The inputs must
never wait for an insertion: every image reaches the node (none lost before it in roscpp's
queues), and each frame is either offered or dropped as worker_behind once the worker catches
up. While the burst runs, the services answer from the selection so far.

When the inputs wait for the worker (as they did before issue 21: push() took the state lock
that an insertion holds), the input thread stops for the 4 s insertion, roscpp's queue of 100
frames overflows and frames are lost before the node: this test fails (checked with push()
taking the state lock again: 44 frames lost before the node)."""
import threading
import time
import unittest

import rospy
import rostest

from view_selection.srv import GetNextViews, GetNextViewsRequest, GetSelection

from vs_robust import (FramePublisher, NodeProcess, Statistics, call, check_statistics,
                       find_tool, frame_drops, synthetic_frames, wait_until)

PKG = 'view_selection'
FRAMES = 300
RATE = 30.0


class WorkerBehind(unittest.TestCase):
    def test_a_burst_outrunning_a_slow_worker_loses_nothing_before_the_node(self):
        binary = find_tool('slow_points_node')
        self.assertTrue(binary, 'slow_points_node is not built')
        publisher = FramePublisher('/burst/camera')
        # Shipped defaults but for what the test's frames need: poses on a topic, and the
        # test binary's own delay.
        node = NodeProcess('burst_node', {'pose_source': 'topic', 'slow_point_source_ms': 200.0,
                            'slow_point_source_stall_ms': 4000.0},
                           remaps=publisher.remaps(), binary=binary).start()
        try:
            node.wait_for_services()
            statistics = Statistics(node.name)
            publisher.wait_connected()
            # 0.15 m apart, 2 m from the wall: every frame passes the motion policy's 0.1 m.
            # 0.3 m a frame 2 m from the wall (8.5 deg): every frame a keyframe under every policy
            frames = synthetic_frames(FRAMES, step=0.3)
            answers, errors = [], []
            done = threading.Event()

            def ask():
                while not done.is_set():
                    try:
                        got = call(node.name + '/get_selection', GetSelection, timeout=10.0)
                        answers.append(len(got.selection.keyframes))
                        call(node.name + '/get_next_views', GetNextViews,
                             GetNextViewsRequest(view=0, after_completion=True), timeout=10.0)
                    except AssertionError as e:
                        errors.append(str(e))
                    time.sleep(0.2)
            asker = threading.Thread(target=ask)
            asker.start()
            start = time.time()
            for i, frame in enumerate(frames):
                publisher.publish(frame)
                delay = start + (i + 1) / RATE - time.time()
                if delay > 0:
                    time.sleep(delay)
            done.set()
            asker.join(30.0)
            self.assertEqual(errors, [], 'the services must answer during the burst')
            self.assertTrue(answers, 'no service answer during the burst')
            # The worker catches up: every frame that reached the node offered or dropped, and
            # nothing more arrives.
            settled = {'counts': None, 'since': time.time()}

            def handled(m):  # frames offered or dropped (not inputs that never became frames)
                return m.frames_offered + frame_drops(m)

            def caught_up():
                m = statistics.get()
                if m is None or handled(m) != m.frames_received:
                    return False
                counts = (m.images_arrived, m.frames_received, handled(m))
                if counts != settled['counts']:
                    settled.update(counts=counts, since=time.time())
                return time.time() - settled['since'] > 3.0
            wait_until(caught_up, 120.0, 'the worker catching up', period=0.2)
            s = statistics.get()
            drops = dict(zip(s.drop_reasons, s.drop_counts))
            rospy.loginfo('burst: %d offered, drops %s', s.frames_offered, drops)
            self.assertEqual(s.images_arrived, FRAMES, 'every image reaches the node')
            self.assertEqual(drops.get('lost_before_node', 0), 0,
                             'frames were lost in roscpp\'s queues: the inputs waited: %s' % drops)
            self.assertEqual(drops.get('unsynchronised', 0), 0, drops)
            self.assertGreater(drops.get('worker_behind', 0), 0,
                               'the burst must outrun the slow worker (else this tests nothing)')
            self.assertEqual(set(drops) - {'worker_behind'}, set(),
                             'only worker_behind drops expected: %s' % drops)
            self.assertEqual(s.frames_offered + drops['worker_behind'], FRAMES)
            self.assertGreater(s.keyframes, FRAMES // 10, 'the slow insertions ran')
            check_statistics(self, s, 'after the burst')
            # The selection has every keyframe offered.
            got = call(node.name + '/get_selection', GetSelection, timeout=10.0)
            self.assertEqual(len(got.selection.keyframes), s.keyframes)
            self.assertTrue(node.alive(), node.output()[-3000:])
        finally:
            node.stop()


if __name__ == '__main__':
    rospy.init_node('worker_behind_tester')
    rostest.rosrun(PKG, 'worker_behind', WorkerBehind)
