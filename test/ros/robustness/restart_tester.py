#!/usr/bin/env python3
"""Nothing accepted is lost: a session killed with SIGKILL after an autosave and started again
continues from ~state_file; once the frames after the saved one are replayed, its selection equals
an uninterrupted node's, message for message. select_views --state re-selects the same file. A
truncated, corrupted, foreign or incompatible file gives one error, an empty start, and is kept
aside, never overwritten.

Frames: the first ~max_frames of ~dataset (default ../shared/data/redkitchen-0-499) through
tum_to_bag, else the built-in synthetic sequence (generate_sequence)."""
import json
import os
import shutil
import struct
import sys
import tempfile
import threading
import time
import unittest

import rospy
import rostest
from std_srvs.srv import Trigger

from view_selection.srv import Export, ExportRequest, GetSelection

from vs_robust import (FramePublisher, NodeProcess, Statistics, bag_frames, call,
                       check_selection, check_statistics, feed, find_tool, note_without_real_data,
                       serialized)
from vs_replay import play_bag, run, wait_for_subscribers, wait_until_processed

PKG = 'view_selection'
# test_5: the kitchen's first 240 frames give 15 keyframes at the shipped parameters; the kill
# comes at about half of them.
REPLAY_FRAMES = 240


def registration_log(path):
    """(keyframe id, stamp) of each record of a registration log (docs/state_file.md, "The
    registration log"), checking each record's CRC."""
    import zlib
    with open(path, 'rb') as f:
        data = f.read()
    out, at = [], 0
    while at < len(data):
        tag, length = struct.unpack_from('<4sI', data, at)
        assert tag == b'VSRG', 'record at byte %d of %s: tag %r' % (at, path, tag)
        payload = data[at + 8:at + 8 + length]
        (crc,) = struct.unpack_from('<I', data, at + 8 + length)
        assert crc == zlib.crc32(payload), 'record at byte %d of %s: CRC' % (at, path)
        out.append(struct.unpack_from('<id', payload))
        at += 8 + length + 4
    return out
KILL_AT_KEYFRAMES = 8

# The session's method (as test/ros/replay/replay.yaml: ~20 keyframes in 120 kitchen frames); the
# waits and queues are the shipped ones (the frames are fed a few at a time, each waited for).
PARAMS = {
    'pose_source': 'topic', 'world_frame': '/world', 'keyframe_policy': 'motion',
    'min_translation': 0.05, 'min_rotation_deg': 5.0, 'k': 5, 'point_source': 'depth',
}


class Restart(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_restart_')
        max_frames = int(rospy.get_param('~max_frames', 120))
        dataset = rospy.get_param('~dataset', '')
        tum_to_bag = find_tool('tum_to_bag')
        assert tum_to_bag, 'tum_to_bag is not built'
        if not (dataset and os.path.isdir(dataset)):
            note_without_real_data('restart: synthetic frames', dataset)
            generate = find_tool('generate_sequence')
            assert generate, 'generate_sequence is not built'
            dataset = os.path.join(cls.tmp, 'synthetic')
            run([generate, '--out', dataset, '--frames', str(max(max_frames, REPLAY_FRAMES)), '--quiet', '--width', '320',
                 '--height', '240'], 600, 'generate_sequence')
        cls.dataset = dataset
        bag = os.path.join(cls.tmp, 'frames.bag')
        run([tum_to_bag, '--dataset', dataset, '--out', bag, '--max-frames', str(max_frames),
             '--quiet'], 600, 'tum_to_bag')
        cls.frames = bag_frames(bag)
        assert len(cls.frames) >= 40, 'too few frames in %s' % bag
        rospy.loginfo('restart test: %d frames from %s', len(cls.frames), dataset)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    # -------------------------------------------------------------------------------------------
    def start(self, name, extra=None):
        pub = FramePublisher('/%s/camera' % name)
        params = dict(PARAMS)
        params.update(extra or {})
        node = NodeProcess(name, params, pub.remaps()).start()
        node.wait_for_services()
        pub.wait_connected()
        return node, pub

    def feed(self, frames, targets):
        """Publishes each frame to every (publisher, statistics) target and waits until each node
        has handled it, a few frames ahead of the slower node at most (vs_robust.feed: no frame
        lost to a queue, the same frames in the same order)."""
        for _, s in targets:
            s.wait(lambda m: True, 30, 'statistics')  # a count to start from
        before = [s.handled() for _, s in targets]

        def publish(f):
            for pub, _ in targets:
                pub.publish(f)
        feed(publish, frames, lambda: min(s.handled() - b for (_, s), b in zip(targets, before)), 30,
             ' and '.join(s.node for _, s in targets))

    def index_after(self, stamp):
        """Index of the first frame after `stamp` (0 for a zero stamp)."""
        for i, f in enumerate(self.frames):
            if f.stamp > stamp:
                return i
        return len(self.frames)

    # -------------------------------------------------------------------------------------------
    def test_1_killed_session_continues_exactly(self):
        state = os.path.join(self.tmp, 'state', 'session.state')
        half = len(self.frames) // 2
        ref, ref_pub = self.start('restart_ref', {'save_keyframe_images': True})
        node, pub = self.start('restart_node', {'state_file': state, 'autosave_keyframes': 3,
                                                'save_keyframe_images': True})
        ref_stats, stats = Statistics(ref.name), Statistics(node.name)
        try:
            both = [(ref_pub, ref_stats), (pub, stats)]
            self.feed(self.frames[:half], both)
            stats.wait(lambda s: s.state_saved_keyframes >= 3, 30, 'an autosave')
            self.assertTrue(os.path.isfile(state), 'no state file after an autosave')
            # On until the node holds a keyframe and a few frames the last autosave does not.
            kill_at = half
            while kill_at < len(self.frames) - 10:
                s = stats.get()
                unsaved = kill_at - self.index_after(s.state_saved_frame_stamp)
                if s.keyframes > s.state_saved_keyframes and unsaved >= 4:
                    break
                self.feed(self.frames[kill_at:kill_at + 1], both)
                kill_at += 1
            if s.state_saved_keyframes >= 6:
                # The first autosave writes the whole file, later ones append journal records.
                self.assertGreater(os.path.getsize(state + '.journal'), 0,
                                   'a later autosave appended nothing to the journal')
            # SIGKILL: no shutdown save, so frames after the last autosave are lost to the node.
            node.kill()
            rospy.loginfo('restart test: killed after frame %d with %d keyframes, %d saved, %d '
                          'frames to replay', kill_at, s.keyframes, s.state_saved_keyframes,
                          kill_at - self.index_after(s.state_saved_frame_stamp))

            stats.forget()
            node.start()
            node.wait_for_services()
            pub.wait_connected()
            restored = stats.wait(lambda s: True, 20, 'statistics after the restart')
            self.assertGreater(restored.keyframes, 0, 'the restarted node did not continue')
            self.assertEqual(restored.keyframes, restored.state_saved_keyframes)
            resume = self.index_after(restored.last_frame_stamp)
            self.assertEqual(restored.frames_received, resume,
                             'a continued session has handled exactly the frames up to the saved one')
            self.assertLess(resume, kill_at, 'nothing was lost: the kill came too late to test')
            # The frames between the last autosave and the kill, to this node only; then the rest
            # to both.
            self.feed(self.frames[resume:kill_at], [(pub, stats)])
            self.feed(self.frames[kill_at:], both)

            a = call(ref.name + '/get_selection', GetSelection).selection
            b = call(node.name + '/get_selection', GetSelection).selection
            check_selection(self, b, 'restarted node')
            self.assertGreater(len(a.keyframes), 5)
            self.assertEqual([k.stamp for k in b.keyframes], [k.stamp for k in a.keyframes])
            self.assertEqual(serialized(b), serialized(a),
                             'the restarted session\'s selection differs from the uninterrupted one')
            sa, sb = ref_stats.get(), stats.get()
            check_statistics(self, sb, 'restarted node')
            for field in ('frames_received', 'frames_offered', 'keyframes', 'frames_dropped'):
                self.assertEqual(getattr(sb, field), getattr(sa, field), field)
            self.assertEqual(sb.frames_received, len(self.frames))

            # Images are not in the state file: the continued keyframes have none, and every
            # image written is the same keyframe's as the uninterrupted node's.
            exports = {}
            for n in (ref, node):
                folder = os.path.join(self.tmp, 'export' + n.name.replace('/', '_'))
                answer = call(n.name + '/export', Export, ExportRequest(directory=folder), 60)
                self.assertTrue(answer.success, answer.message)
                exports[n.name] = (folder, answer)
            folder, answer = exports[node.name]
            self.assertEqual(answer.images_written, len(b.keyframes) - restored.keyframes,
                             answer.message)
            self.assertIn('continued from ~state_file have no image', answer.message)
            for k in b.keyframes[restored.keyframes:]:
                with open(os.path.join(folder, k.image_name), 'rb') as x, \
                        open(os.path.join(exports[ref.name][0], k.image_name), 'rb') as y:
                    self.assertEqual(x.read(), y.read(), 'image of ' + k.image_name)
            for k in b.keyframes[:restored.keyframes]:
                self.assertFalse(os.path.exists(os.path.join(folder, k.image_name)), k.image_name)

            # SIGINT: the node saves on the way out; select_views re-selects that file.
            self.assertEqual(node.stop(), 0)
            out = os.path.join(self.tmp, 'offline')
            summary = run([find_tool('select_views'), '--state', state, '--out', out, '--quiet',
                           '--print-sets', '0'], 120, 'select_views --state')
            with open(os.path.join(out, 'selection.json')) as f:
                offline = json.load(f)
            self.assertEqual(len(offline['keyframes']), len(a.keyframes), summary)
            self.assertEqual(offline['pairs'], [[p.first, p.second] for p in a.pairs])
            self.assertEqual(offline['next_views'], [list(v.next_views) for v in a.next_view_sets])
            self.assertEqual(offline['start_view'], a.start_view)
            # Other selection parameters re-select the same keyframes offline.
            run([find_tool('select_views'), '--state', state, '--out', out + '_k3', '--k', '3',
                 '--quiet'], 120, 'select_views --state --k 3')
            with open(os.path.join(out + '_k3', 'selection.json')) as f:
                self.assertTrue(all(len(s) <= 3 for s in json.load(f)['next_views']))
        finally:
            for n in (ref, node):
                n.stop()
            for s in (ref_stats, stats):
                s.close()
            for p in (ref_pub, pub):
                p.close()

    def test_2_save_state_service(self):
        state = os.path.join(self.tmp, 'service', 'session.state')
        node, pub = self.start('save_service', {'state_file': state, 'autosave_keyframes': 0})
        stats = Statistics(node.name)
        try:
            self.feed(self.frames[:10], [(pub, stats)])
            self.assertFalse(os.path.exists(state), 'autosave_keyframes 0 saved anyway')
            answer = call(node.name + '/save_state', Trigger, timeout=30)
            self.assertTrue(answer.success, answer.message)
            self.assertIn('keyframes', answer.message)
            self.assertTrue(os.path.isfile(state))
            s = stats.wait(lambda s: s.state_saved_keyframes > 0, 10, 'saved keyframes reported')
            self.assertEqual(s.state_saved_keyframes, s.keyframes)
            # Without ~state_file the service says saving is off.
            off, off_pub = self.start('save_off')
            try:
                answer = call(off.name + '/save_state', Trigger)
                self.assertFalse(answer.success)
                self.assertIn('state_file', answer.message)
            finally:
                off.stop()
                off_pub.close()
        finally:
            node.stop()
            stats.close()
            pub.close()

    def good_state_file(self):
        """A real state file of a few keyframes."""
        path = os.path.join(self.tmp, 'good', 'session.state')
        if not os.path.exists(path):
            node, pub = self.start('good_state', {'state_file': path})
            stats = Statistics(node.name)
            try:
                self.feed(self.frames[:12], [(pub, stats)])
            finally:
                self.assertEqual(node.stop(), 0)
                stats.close()
                pub.close()
        with open(path, 'rb') as f:
            return f.read()

    def test_3_bad_state_files_are_kept_aside(self):
        good = self.good_state_file()
        self.assertGreater(len(good), 1000)
        flipped = bytearray(good)
        flipped[len(good) // 2] ^= 0x40
        cases = [('truncated', good[:len(good) // 3], 'truncated'),
                 ('corrupted', bytes(flipped), 'corrupted'),
                 ('foreign', b'\x89PNG\r\n\x1a\n' + b'\0' * 64, 'not a view_selection state file'),
                 ('empty', b'', 'empty')]
        for name, content, reason in cases:
            folder = os.path.join(self.tmp, 'bad_' + name)
            os.makedirs(folder)
            path = os.path.join(folder, 'session.state')
            with open(path, 'wb') as f:
                f.write(content)
            node, pub = self.start('bad_' + name, {'state_file': path})
            try:
                selection = call(node.name + '/get_selection', GetSelection).selection
                self.assertEqual(len(selection.keyframes), 0, name + ': started with keyframes')
                aside = [f for f in os.listdir(folder) if f.startswith('session.state.bad-')]
                self.assertEqual(len(aside), 1, '%s: kept aside as %s' % (name, os.listdir(folder)))
                with open(os.path.join(folder, aside[0]), 'rb') as f:
                    self.assertEqual(f.read(), content, name + ': the kept file was changed')
                errors = [l for l in node.output().splitlines() if 'cannot continue the session' in l]
                self.assertEqual(len(errors), 1, '%s: one error line, got:\n%s' % (name, node.output()))
                self.assertIn(reason, errors[0])
                # The node works and saves a new file beside the kept one.
                answer = call(node.name + '/save_state', Trigger, timeout=30)
                self.assertTrue(answer.success, answer.message)
                self.assertTrue(os.path.isfile(path))
                with open(os.path.join(folder, aside[0]), 'rb') as f:
                    self.assertEqual(f.read(), content, name + ': the kept file was overwritten')
            finally:
                node.stop()
                pub.close()

    def test_4_another_point_source_cannot_continue(self):
        good = self.good_state_file()
        folder = os.path.join(self.tmp, 'other_source')
        os.makedirs(folder)
        path = os.path.join(folder, 'session.state')
        with open(path, 'wb') as f:
            f.write(good)
        node, pub = self.start('other_source', {'state_file': path, 'grid': 8})
        try:
            selection = call(node.name + '/get_selection', GetSelection).selection
            self.assertEqual(len(selection.keyframes), 0)
            self.assertIn("point source 'depth'", node.output())
            aside = [f for f in os.listdir(folder) if f.startswith('session.state.bad-')]
            self.assertEqual(len(aside), 1, os.listdir(folder))
        finally:
            node.stop()
            pub.close()


    # -------------------------------------------------------------------------------------------
    def test_5_killed_during_a_bag_replay_continues_exactly(self):
        """The restart check as a user meets it: a TUM-layout bag played at 1x through a node at
        the shipped parameters (tf poses, the scale_free policy) with ~state_file and an autosave
        after every keyframe (a user who wants a SIGKILL to lose no keyframe sets that: the
        journal makes each one cost one small record). SIGKILL as soon as ~statistics count half
        the keyframes; the node restarts on the state file and the bag plays again from 0.2 s
        before the cut (or before the last frame saved, when that is earlier), so that a frame
        still waiting for its pose at the kill comes again. The
        continued session's selection must equal an uninterrupted node's on the same bag, message
        for message. (The TUM layout's fixed links are re-sent on /tf stamped ahead: a frame just
        after the second play starts needs them before their first message.)"""
        import rosbag
        bag = os.path.join(self.tmp, 'tum_layout.bag')
        run([find_tool('tum_to_bag'), '--dataset', self.dataset, '--out', bag, '--layout', 'tum',
             '--max-frames', str(REPLAY_FRAMES), '--compression', 'none', '--quiet'], 600, 'tum_to_bag')
        with rosbag.Bag(bag) as b:
            bag_start = b.get_start_time()
            stamps = [m.header.stamp.to_sec() for _, m, _ in b.read_messages(topics=['/camera/rgb/image_color'])]
        state = os.path.join(self.tmp, 'replay_state', 'session.state')
        topics = ['/camera/rgb/image_color', '/camera/rgb/camera_info', '/camera/depth/image', '/tf']
        remaps = {'image': topics[0], 'camera_info': topics[1], 'depth': topics[2]}
        shipped = {'world_frame': '/world'}  # the bag's frame ids; everything else shipped
        kept = dict(shipped, state_file=state, autosave_keyframes=1)
        rospy.set_param('/use_sim_time', True)  # the nodes follow the bag's clock
        ref = NodeProcess('replay_uninterrupted', shipped, remaps).start()
        node = NodeProcess('replay_killed', kept, remaps).start()
        ref_stats, stats = Statistics(ref.name), Statistics(node.name)
        try:
            for n in (ref, node):
                n.wait_for_services()
            wait_for_subscribers({ref.name: topics, node.name: topics}, 60)
            frames = len(stamps)
            # The kill: from a thread of its own as soon as the count is reached.
            kill_at = [None]

            def killer():
                half = KILL_AT_KEYFRAMES
                while node.alive():
                    s = stats.get()
                    if s is not None and s.keyframes >= half:
                        node.kill()
                        kill_at[0] = s
                        return
                    time.sleep(0.005)
            watcher = threading.Thread(target=killer)
            watcher.start()
            play_bag(bag, 1.0, {ref.name: topics, node.name: topics}, frames, 60,
                     60.0 + 3.0 * frames / 30.0, counted=[ref.name])
            watcher.join(30)
            self.assertIsNotNone(kill_at[0], 'the node was not killed: too few keyframes')
            wait_until_processed([ref.name], 60)
            a = call(ref.name + '/get_selection', GetSelection).selection
            ref.stop()
            self.assertGreater(len(a.keyframes), kill_at[0].keyframes + 3,
                               'the kill came too late in the bag to test anything')
            cut = kill_at[0].last_frame_stamp.to_sec()

            stats.forget()
            node.start()
            node.wait_for_services()
            wait_for_subscribers({node.name: topics}, 60)
            restored = stats.wait(lambda s: True, 20, 'statistics after the restart')
            rospy.loginfo('restart replay: killed at %d keyframes (%d saved), cut %.3f; %d keyframes continued',
                          kill_at[0].keyframes, kill_at[0].state_saved_keyframes, cut, restored.keyframes)
            self.assertGreater(restored.keyframes, 0, 'the restarted node did not continue')
            # From 0.2 s before the cut, or before the last frame saved when the autosave of the
            # last keyframe was not on disk yet at the kill (then the frames after the saved one
            # come again too, and none is lost: a frame played just after the start stamped
            # before the first motion-capture transform of the second play could get no pose).
            saved = restored.last_frame_stamp.to_sec()
            start = max(0.0, min(cut, saved if saved > 0 else cut) - 0.2 - bag_start)
            rest = sum(1 for t in stamps if t >= bag_start + start)
            play_bag(bag, 1.0, {node.name: topics}, rest, 60, 60.0 + 3.0 * rest / 30.0, start=start)
            wait_until_processed([node.name], 60)
            b = call(node.name + '/get_selection', GetSelection).selection
            self.assertEqual([k.stamp for k in b.keyframes], [k.stamp for k in a.keyframes],
                             'the restarted session\'s keyframes differ from the uninterrupted one\'s')
            self.assertEqual(serialized(b), serialized(a),
                             'the restarted session\'s selection differs from the uninterrupted one')
            # What the revisit rule's registration kept of each keyframe is in the registration
            # log beside the state file: one record per keyframe, the continued ones' read back at
            # the restart (any record of a keyframe the kill lost was dropped then) and the later
            # ones appended, each naming its keyframe by id and stamp.
            records = registration_log(state + '.registration')
            ids = [i for i, _ in records]
            self.assertEqual(ids, sorted(set(ids)), 'one record per keyframe, in order')
            for i, stamp in records:
                self.assertAlmostEqual(stamp, b.keyframes[i].stamp.to_sec(), places=6,
                                       msg='record of keyframe %d' % i)
            self.assertGreaterEqual(len(records), 0.9 * len(b.keyframes),
                                    'nearly every kitchen keyframe has features with depth')
            self.assertTrue(any(i < restored.keyframes for i in ids) and
                            any(i >= restored.keyframes for i in ids))
            s = stats.get()
            drops = dict(zip(s.drop_reasons, s.drop_counts))
            # Only the frames played again before the saved one are dropped, as not after it.
            self.assertEqual(set(drops) - {'out_of_order_stamp', 'duplicate_stamp'}, set(),
                             '%s (cut %.3f, saved %.3f, replay from %.3f; last: %s)' % (
                                 drops, cut, saved, bag_start + start, s.last_error))
        finally:
            rospy.set_param('/use_sim_time', False)
            for n in (ref, node):
                n.stop()
            for st in (ref_stats, stats):
                st.close()


if __name__ == '__main__':
    rospy.init_node('restart_tester')
    rostest.rosrun(PKG, 'restart', Restart, sys.argv)
