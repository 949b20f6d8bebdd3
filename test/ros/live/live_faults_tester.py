#!/usr/bin/env python3
"""The live hand-off when things go wrong (issue 18): colmap_bridge on an unusable project folder,
on a full disk, without COLMAP and with a COLMAP that fails; the node asked to write images where
it cannot; and the pair stream's sequence across a node restart on ~state_file. Every case gets a
clear error, and the view selection node keeps running and answering."""
import json
import os
import signal
import stat
import sys
import tempfile
import time
import unittest

import rospy
import rostest
from std_srvs.srv import Trigger

from view_selection.srv import (GetPairs, GetPairsRequest, GetSelection, WriteKeyframeImages,
                                WriteKeyframeImagesRequest)

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_robust import (FramePublisher, NodeProcess, Statistics, call, feed, find_tool,  # noqa: E402
                       shut_down, synthetic_frames, wait_until)
from faults_tester import small_file_system, umount  # noqa: E402
from view_selection.colmap.model import read_model  # noqa: E402

NODE = '/live_faults_vs'


class LiveFaults(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_live_faults_')
        cls.bridge = find_tool('colmap_bridge')
        assert cls.bridge, 'colmap_bridge is not built'
        cls.pub = FramePublisher(NODE + '/camera')
        cls.state_file = os.path.join(cls.tmp, 'session.vss')
        cls.node = NodeProcess(NODE, {'pose_source': 'topic', 'state_file': cls.state_file},
                               cls.pub.remaps()).start()
        cls.node.wait_for_services()
        cls.pub.wait_connected()
        cls.stats = Statistics(NODE)
        cls.frames = synthetic_frames(160, width=320, height=240, step=0.02)
        cls.published = 0
        cls.publish(40)  # 0.02 m a frame 2 m from the wall: a keyframe every ~9 frames (5 deg parallax)
        cls.stats.wait(lambda s: s.keyframes >= 4, 20, 'keyframes')

    @classmethod
    def publish(cls, count):
        """The next `count` frames, each waited for (offered or dropped), a few in flight
        (vs_robust.feed)."""
        before = cls.published
        feed(cls.pub.publish, cls.frames[before:before + count], lambda: cls.stats.handled() - before, 20, NODE)
        cls.published += count

    @classmethod
    def tearDownClass(cls):
        shut_down(cls.node, cls.stats, cls.pub, folder=cls.tmp)

    def assert_node_serves(self):
        self.assertTrue(self.node.alive(), 'the view selection node died')
        answer = call(NODE + '/get_selection', GetSelection, None, 10.0)
        self.assertTrue(answer.success)
        self.assertGreaterEqual(len(answer.selection.keyframes), 4)

    def start_bridge(self, name, params):
        params = dict(params, node=NODE)
        return NodeProcess(name, params, binary=self.bridge).start()

    def assert_exits_with(self, bridge, text):
        code = bridge.wait(60)
        self.assertNotEqual(0, code, bridge.output()[-2000:])
        self.assertIn(text, bridge.output())

    # -------------------------------------------------------------------------------------------
    def test_a_project_folder_that_cannot_be_made(self):
        blocker = os.path.join(self.tmp, 'a_file')
        open(blocker, 'w').close()
        bridge = self.start_bridge('/bridge_no_folder', {'project': os.path.join(blocker, 'project')})
        self.assert_exits_with(bridge, 'cannot use the project folder')
        # The node asked to write its images there: a clear answer, nothing else changes.
        answer = call(NODE + '/write_keyframe_images', WriteKeyframeImages,
                      WriteKeyframeImagesRequest(directory=os.path.join(blocker, 'images')), 10.0)
        self.assertFalse(answer.success)
        self.assertIn('cannot make folder', answer.message)
        self.assert_node_serves()

    def test_colmap_missing(self):
        bridge = self.start_bridge('/bridge_no_colmap', {'project': os.path.join(self.tmp, 'no_colmap'),
                                                         'colmap': os.path.join(self.tmp, 'nowhere', 'colmap')})
        self.assert_exits_with(bridge, 'not found: install COLMAP')
        self.assert_node_serves()

    def test_colmap_failing(self):
        """A COLMAP whose matching fails: the bridge stays up and says why; ~finish still writes
        the model (without matches: no points) and names every pair it skipped and the reason,
        in its answer, report.json and ledger.txt; the node is untouched."""
        fake = os.path.join(self.tmp, 'failing_colmap')
        with open(fake, 'w') as f:
            f.write('#!/bin/sh\n[ "$1" = matches_importer ] && { echo "simulated failure" >&2; exit 3; }\n'
                    'exec colmap "$@"\n')
        os.chmod(fake, stat.S_IRWXU)
        # ~matcher colmap: COLMAP's own pipeline (a user without poses they trust), where every
        # pair goes through the failing matches_importer.
        bridge = self.start_bridge('/bridge_failing', {'project': os.path.join(self.tmp, 'failing'),
                                                       'colmap': fake, 'batch_period': 0.2, 'matcher': 'colmap'})
        try:
            rospy.wait_for_service(bridge.name + '/finish', timeout=60)
            images = os.path.join(self.tmp, 'failing', 'images')
            wait_until(lambda: call(NODE + '/get_pairs', GetPairs, GetPairsRequest(since=0), 10.0).keyframe_image_dir
                       == images, 30, 'the node writes images into the project')
            self.publish(40)  # new keyframes: their images go into the project
            # (An idle finish may be running: ~finish waits for it and then finishes again.)
            answer = wait_until(lambda: (lambda a: a if a.message != 'a finish is running' else None)(
                call(bridge.name + '/finish', Trigger, None, 300.0)), 300, '~finish', period=0.5)
            self.assertIn('skipped', answer.message)
            self.assertIn('matches_importer', answer.message)
            self.assertIn('failed (exit 3)', answer.message)
            project = os.path.join(self.tmp, 'failing')
            with open(os.path.join(project, 'report.json')) as f:
                report = json.load(f)
            self.assertGreater(len(report['skipped']['pairs']), 0)
            self.assertEqual(report['pairs_matched'], 0)
            self.assertTrue(all('failed (exit 3)' in s['error'] for s in report['skipped']['pairs']), report['skipped'])
            with open(os.path.join(project, 'ledger.txt')) as f:
                ledger = f.read()
            self.assertNotIn(' matched ', ledger)
            self.assertTrue(bridge.alive(), 'the bridge died when COLMAP failed')
            self.assert_node_serves()
        finally:
            bridge.stop(60)

    def test_a_full_disk(self):
        folder = small_file_system(self, os.path.join(self.tmp, 'full'), '300k')
        bridge = None
        try:
            bridge = self.start_bridge('/bridge_full', {'project': folder, 'batch_period': 0.2})
            rospy.wait_for_service(bridge.name + '/finish', timeout=60)
            wait_until(lambda: call(NODE + '/get_pairs', GetPairs, GetPairsRequest(since=0), 10.0).keyframe_image_dir
                       == os.path.join(folder, 'images'), 30, 'the node writes images into the project')
            # New keyframes: the node writes their images until the disk is full, then counts
            # each lost one with a throttled error, and goes on.
            self.publish(30)
            self.assert_node_serves()
            answer = call(bridge.name + '/finish', Trigger, None, 300.0)
            self.assertFalse(answer.success, 'a model on a full disk: ' + answer.message)
            self.assertTrue(bridge.alive(), 'the bridge died on a full disk')
            self.assertIn('No space left on device', self.node.output() + bridge.output() + answer.message +
                          open(os.path.join(folder, 'colmap.log')).read() if os.path.exists(
                              os.path.join(folder, 'colmap.log')) else self.node.output() + answer.message)
            self.assert_node_serves()
        finally:
            if bridge:
                bridge.stop(60)
            # The node writes no more images there.
            call(NODE + '/write_keyframe_images', WriteKeyframeImages, WriteKeyframeImagesRequest(directory=''), 10.0)
            umount(folder)

    def test_the_model_is_written_when_the_bridge_is_stopped(self):
        """SIGINT (roslaunch stopping it, or Ctrl-C) while it has work: the model is written from
        what was announced, and the bridge exits by itself before roslaunch would escalate to
        SIGTERM (15 s). ~finish_after_idle 0: a user who wants the model only on ~finish and at
        shutdown."""
        folder = os.path.join(self.tmp, 'stopped')
        bridge = self.start_bridge('/bridge_stopped', {'project': folder, 'finish_after_idle': 0.0})
        try:
            rospy.wait_for_service(bridge.name + '/finish', timeout=60)
            wait_until(lambda: call(NODE + '/get_pairs', GetPairs, GetPairsRequest(since=0), 10.0).keyframe_image_dir
                       == os.path.join(folder, 'images'), 30, 'the node writes images into the project')
            self.publish(30)  # keyframes, their images and pairs: work for the bridge
            ledger = os.path.join(folder, 'ledger.txt')
            # Two images with features at least: a model needs two (with one, the shutdown's
            # finish rightly says so and writes none).
            wait_until(lambda: os.path.exists(ledger) and open(ledger).read().count(' extracted ') >= 2, 60,
                       'the bridge at work')
            self.assertFalse(os.path.exists(os.path.join(folder, 'report.json')))
            bridge.signal(signal.SIGINT)
            code = bridge.wait(15.0)  # roslaunch's SIGINT timeout (then SIGTERM, then SIGKILL)
            self.assertEqual(0, code, bridge.output()[-3000:])
            self.assertTrue(os.path.exists(os.path.join(folder, 'report.json')), bridge.output()[-3000:])
            report = json.load(open(os.path.join(folder, 'report.json')))
            self.assertEqual('shutdown', report['why'])
            self.assertGreaterEqual(report['registered'], 2)
            self.assertTrue(os.path.isdir(os.path.join(folder, 'sparse', '0')))
            self.assert_node_serves()
        finally:
            if bridge.alive():
                bridge.kill()

    def test_the_shutdown_during_a_finish_writes_the_model_within_the_budget(self):
        """SIGINT while a finish (an idle one, started with no deadline) is refining, with a
        refine_model that would take for ever (a stand-in on ~refine_tool that hangs; the real
        one is bounded by ~refine_max_seconds, but its reading and writing are not, issue 35):
        the finish gets the shutdown's deadline, refine_model is killed there, and the model is
        on disk, unrefined, with report.json saying so, before roslaunch would escalate (15 s)."""
        folder = os.path.join(self.tmp, 'finishing')
        refining = os.path.join(self.tmp, 'refining')
        tool = os.path.join(self.tmp, 'hanging_refine_model')
        with open(tool, 'w') as f:
            f.write('#!/bin/sh\ntouch %s\nexec sleep 3600\n' % refining)
        os.chmod(tool, stat.S_IRWXU)
        bridge = self.start_bridge('/bridge_finishing', {'project': folder, 'refine_tool': tool})
        try:
            rospy.wait_for_service(bridge.name + '/finish', timeout=60)
            wait_until(lambda: call(NODE + '/get_pairs', GetPairs, GetPairsRequest(since=0), 10.0).keyframe_image_dir
                       == os.path.join(folder, 'images'), 30, 'the node writes images into the project')
            # 80 frames more (the wall is further away this late, so keyframes come more slowly:
            # four or so, with their images here); the frames after the 160th see another wall.
            cls = type(self)
            cls.frames = cls.frames + synthetic_frames(cls.published + 80, width=320, height=240,
                                                       step=0.02)[len(cls.frames):]
            self.publish(80)
            try:
                wait_until(lambda: os.path.exists(refining), 120, 'the idle finish refining', period=0.1)
            except AssertionError as e:
                raise AssertionError('%s; the bridge said:\n%s' % (e, bridge.output()[-3000:]))
            # (An earlier idle finish, with no pair verified yet, wrote a model without refining.)
            start, signalled = time.monotonic(), time.time()
            bridge.signal(signal.SIGINT)
            code = bridge.wait(15.0)  # roslaunch's SIGINT timeout (then SIGTERM, then SIGKILL)
            took = time.monotonic() - start
            self.assertEqual(0, code, bridge.output()[-3000:])
            self.assertLess(took, 12.0 + 1.0, 'the default ~shutdown_budget is 12 s')
            report = json.load(open(os.path.join(folder, 'report.json')))
            self.assertGreater(report['finished_at'], signalled)  # the model of the finish interrupted
            # The idle finish's report, or the shutdown's own finish after it (when the node
            # announced more meanwhile): either way written within the budget and saying what it is.
            self.assertIn(report['complete'], (True, False))
            if not report['complete']:
                self.assertIn('out of time', report['incomplete'])
            if 'refinement' in report:  # refine_model killed at the deadline, or given no time
                self.assertFalse(report['refinement']['refined'])
                self.assertIn('refinement failed', report['refinement']['error'])
            else:  # not tried: out of time before it, or no pair verified
                self.assertTrue(not report['complete'] or report.get('model_error'), report)
            # Every keyframe whose image the node wrote here (the earlier ones' it no longer has);
            # out of time, those the live model had (a keyframe that came at the end has no
            # features yet).
            self.assertGreaterEqual(report['registered'], 2)
            with_images = report['keyframes'] - len(report['images_missing'])
            if report['complete']:
                self.assertEqual(with_images, report['registered'])
            else:
                self.assertLessEqual(report['registered'], with_images)
            self.assertEqual(report['registered'], len(read_model(os.path.join(folder, 'sparse', '0')).images))
            self.assert_node_serves()
        finally:
            if bridge.alive():
                bridge.kill()

    def test_z_the_sequence_continues_after_a_restart(self):
        before = call(NODE + '/get_pairs', GetPairs, GetPairsRequest(since=0), 10.0)
        self.assertTrue(before.success)
        self.assertGreater(before.sequence, 0)
        pairs = {(p.first, p.second) for p in before.changes[0].added}
        self.assertEqual(0, self.node.stop(30))  # saves the session
        self.node.start()
        self.node.wait_for_services()
        after = call(NODE + '/get_pairs', GetPairs, GetPairsRequest(since=before.sequence), 10.0)
        self.assertGreater(after.sequence, before.sequence, 'the sequence started over')
        whole = after.changes[0]
        self.assertTrue(whole.full)
        selection = call(NODE + '/get_selection', GetSelection, None, 10.0).selection
        self.assertEqual({(p.first, p.second) for p in selection.pairs}, {(p.first, p.second) for p in whole.added})
        self.assertTrue(pairs <= {(p.first, p.second) for p in whole.added} | pairs)


if __name__ == '__main__':
    rospy.init_node('live_faults_tester')
    rostest.rosrun('view_selection', 'live_faults', LiveFaults, sys.argv)
