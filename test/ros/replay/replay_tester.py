#!/usr/bin/env python3
"""Bag-replay rostest: a TUM folder becomes a bag (tum_to_bag), the bag is played with --clock
through view_selection_node (one node per ~pose_source), and each node's selection must equal
select_views's on the same frames with the same parameters.

The data: ~dataset (default ../shared/data/redkitchen-0-499 next to the package), its first
~max_frames frames; when that folder is absent, the built-in synthetic sequence written by
generate_sequence; when that tool is not built either, the test is skipped with a message.
With ~drifted_revisit: a round of the built-in walk at 320 x 240, then the same round again along
the frames in between with its poses placed off the truth (6 degrees, 0.25 m); that revisit must be
recognised from the images.
"""
import json
import os
import subprocess
import sys
import tempfile
import time
import unittest

import rospy
import rostest

from view_selection import geometry
from view_selection.srv import Export, ExportRequest, GetSelection

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_robust import call, find_tool  # noqa: E402,F401  a service call with a timeout
from vs_replay import msg_stamp_ns, play_bag, remove_output, run, stamp_ns, wait_for_subscribers  # noqa: E402,F401

PKG = 'view_selection'


def dense_error_resistance(selection):
    """selection.json's error_resistance as rows of n values (None = +inf), from either format:
    view_selection/1 (dense rows) or view_selection/2 (each row's finite [j, E] entries)."""
    rows = selection['error_resistance']
    if selection['format'] == 'view_selection/1':
        return rows
    dense = [[None] * len(rows) for _ in rows]
    for i, row in enumerate(rows):
        for j, value in row:
            dense[i][j] = value
    return dense


class Replay(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.nodes = rospy.get_param('~nodes').split()
        cls.tolerances = [float(t) for t in str(rospy.get_param('~tolerances')).split()]
        assert len(cls.nodes) == len(cls.tolerances), '~nodes and ~tolerances must pair up'
        cls.rate = float(rospy.get_param('~rate', 0.5))
        cls.max_frames = int(rospy.get_param('~max_frames', 150))
        cls.timeout = float(rospy.get_param('~timeout', 60.0))
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_replay_')
        cls.skip_reason = None
        cls.prepare()

    @classmethod
    def tearDownClass(cls):
        remove_output(cls.tmp, 'replay test')

    # ------------------------------------------------------------------------------------------
    @classmethod
    def prepare(cls):
        """Finds or makes the TUM folder, writes the bag and runs select_views; plays the bag."""
        dataset = rospy.get_param('~dataset', '')
        tum_to_bag, select_views = find_tool('tum_to_bag'), find_tool('select_views')
        if not tum_to_bag or not select_views:
            raise AssertionError('tum_to_bag or select_views is not built (build the package first)')
        cls.revisit = bool(rospy.get_param('~drifted_revisit', False))
        if cls.revisit:
            # A round of the built-in walk, then the same round again along the frames in between,
            # its poses placed off the truth as an odometry's drift places a revisit off its first
            # pass: the revisit rule must recognise it from the images (docs/design.md, "Revisits
            # under drift").
            generate = find_tool('generate_sequence')
            if not generate:
                raise AssertionError('generate_sequence is not built (build the package first)')
            walk = os.path.join(cls.tmp, 'walk')
            run([generate, '--out', walk, '--frames', str(cls.ROUND), '--width', '320', '--height', '240',
                 '--quiet'], 600, 'generate_sequence')
            cls.source = os.path.join(cls.tmp, 'drifted_revisit')
            cls.revisit_stamp, cls.new_ground_stamp = cls.write_drifted_revisit(walk, cls.source)
            cls.max_frames = cls.FIRST + cls.ROUND // 2
        elif dataset and os.path.isdir(dataset):
            cls.source = dataset
        else:
            log = os.environ.get('VIEW_SELECTION_SKIP_LOG')
            rospy.logwarn('replay test: no real data (%s absent); synthetic frames', dataset)
            if log:
                with open(log, 'a') as f:
                    f.write('replay: synthetic frames: no real data (%s absent)\n' % dataset)
            generate = find_tool('generate_sequence')
            if not generate:
                cls.skip_reason = ('no real data: neither %s nor the generate_sequence tool (the built-in synthetic '
                                   'sequence) is available: nothing to replay' % (dataset or '~dataset'))
                return
            cls.source = os.path.join(cls.tmp, 'synthetic')
            run([generate, '--out', cls.source, '--frames', str(cls.max_frames), '--quiet'], 600,
                'generate_sequence')
        rospy.loginfo('replay test: frames from %s', cls.source)

        cls.bag = os.path.join(cls.tmp, 'replay.bag')
        run([tum_to_bag, '--dataset', cls.source, '--out', cls.bag, '--max-frames', str(cls.max_frames),
             '--quiet'], 600, 'tum_to_bag')

        # select_views with the parameters of the first node (the .test gives every node the same).
        cls.offline = os.path.join(cls.tmp, 'offline')
        run([select_views, '--dataset', cls.source, '--max-frames', str(cls.max_frames), '--out', cls.offline,
             '--quiet', '--print-sets', '0'] + cls.select_views_options(cls.nodes[0]), 600, 'select_views')
        with open(os.path.join(cls.offline, 'selection.json')) as f:
            cls.expected = json.load(f)
        with open(os.path.join(cls.offline, 'pairs.txt')) as f:
            cls.expected_pairs_txt = f.read()
        if cls.revisit:
            # The same frames with the rule of the poses alone, for comparison.
            posed = os.path.join(cls.tmp, 'offline_poses_alone')
            options = cls.select_views_options(cls.nodes[0])
            if '--revisit-registration' in options:
                at = options.index('--revisit-registration')
                del options[at:at + 2]
            run([select_views, '--dataset', cls.source, '--max-frames', str(cls.max_frames), '--out', posed,
                 '--quiet', '--print-sets', '0', '--revisit-registration', 'false'] + options, 600, 'select_views')
            with open(os.path.join(posed, 'selection.json')) as f:
                cls.expected_poses_alone = json.load(f)
        cls.frames = min(cls.max_frames, cls.count_frames(cls.bag))

        for node in cls.nodes:
            for name in ('get_selection', 'export'):
                try:
                    rospy.wait_for_service(node + '/' + name, timeout=cls.timeout)
                except rospy.ROSException:
                    raise AssertionError('%s/%s was not advertised within %.0f s' % (node, name, cls.timeout))
        cls.wait_for_subscribers()

        cls.play()
        cls.wait_until_processed()

    ROUND = 290  # frames: a round of the built-in walk (about 280 at its 0.7 m/s) and a little more
    FIRST = 230  # frames of the first pass: the revisit goes on to ground it did not see

    @staticmethod
    def write_drifted_revisit(walk, out):
        """A TUM folder: the walk's first FIRST frames, then its odd frames again up to the end of
        the round (copies named by their new stamps, 1/30 s apart after the last), their poses
        turned 6 degrees about the vertical (z) through the origin and shifted 0.25 m along x.
        Returns the revisit's first stamp and the stamp where it leaves the first pass's ground."""
        import math
        import shutil

        def entries(name):
            with open(os.path.join(walk, name)) as f:
                return [line.split() for line in f if line.strip() and not line.startswith('#')]
        rgb, depth, truth = entries('rgb.txt'), entries('depth.txt'), entries('groundtruth.txt')
        def stamps(rows):
            return [round(float(r[0]), 6) for r in rows]
        assert stamps(rgb) == stamps(depth) == stamps(truth), 'the walk has one pose and depth per image'
        turn = math.radians(6.0)
        drift = geometry.rotation_of((math.cos(turn / 2.0), 0.0, 0.0, math.sin(turn / 2.0)))
        for folder in ('rgb', 'depth'):
            os.makedirs(os.path.join(out, folder))
        shutil.copyfile(os.path.join(walk, 'camera.yaml'), os.path.join(out, 'camera.yaml'))
        lists = {'rgb.txt': [], 'depth.txt': [], 'groundtruth.txt': []}
        first = Replay.FIRST
        last = float(rgb[first - 1][0])
        revisit_stamp = new_ground_stamp = None
        for q in list(range(first)) + list(range(1, len(rgb), 2)):
            again = len(lists['rgb.txt']) >= first
            stamp = '%.6f' % (last + (len(lists['rgb.txt']) - first + 1) / 30.0) if again else rgb[q][0]
            if again and revisit_stamp is None:
                revisit_stamp = float(stamp)
            if again and q >= first and new_ground_stamp is None:
                new_ground_stamp = float(stamp)
            for name, entry in (('rgb.txt', rgb[q]), ('depth.txt', depth[q])):
                folder = name[:-4]
                target = '%s/%s.png' % (folder, stamp)
                shutil.copyfile(os.path.join(walk, entry[1]), os.path.join(out, target))
                lists[name].append('%s %s\n' % (stamp, target))
            x, y, z, qx, qy, qz, qw = (float(a) for a in truth[q][1:8])
            if again:  # turned by `drift` about z, then shifted 0.25 m along x
                x, y, z = drift.dot((x, y, z)) + (0.25, 0.0, 0.0)
                qw, qx, qy, qz = geometry.quaternion_of(drift.dot(geometry.rotation_of((qw, qx, qy, qz))))
            lists['groundtruth.txt'].append(
                '%s %s\n' % (stamp, ' '.join('%.9f' % a for a in (x, y, z, qx, qy, qz, qw))))
        for name, lines in lists.items():
            with open(os.path.join(out, name), 'w') as f:
                f.writelines(lines)
        return revisit_stamp, new_ground_stamp

    @classmethod
    def play(cls):
        """Plays the bag once every node is connected to every topic of the player (play_bag)."""
        topics = ['/camera/rgb/image_color', '/camera/rgb/camera_info', '/camera/depth/image']
        wanted = {node: topics + ['/tf' if rospy.get_param(node + '/pose_source', 'tf') == 'tf' else '/camera/pose']
                  for node in cls.nodes}
        play_bag(cls.bag, cls.rate, wanted, cls.frames, cls.timeout, 30.0 + 2.0 * (cls.frames / 30.0) / cls.rate)

    @classmethod
    def count_frames(cls, bag):
        out = run(['rosbag', 'info', '--yaml', '--key', 'topics', bag], 60, 'rosbag info')
        # lines like "- topic: /camera/rgb/image_color\n  type: ...\n  messages: 150"
        topic = None
        for line in out.splitlines():
            line = line.strip().lstrip('- ')
            if line.startswith('topic:'):
                topic = line.split(':', 1)[1].strip()
            elif line.startswith('messages:') and topic == '/camera/rgb/image_color':
                return int(line.split(':', 1)[1])
        raise AssertionError('the bag %s has no /camera/rgb/image_color:\n%s' % (bag, out))

    @classmethod
    def select_views_options(cls, node):
        """The node's private parameters as select_views options; unset ones keep both defaults."""
        def get(name):
            return rospy.get_param(node + '/' + name, None)
        options = []
        policy = get('keyframe_policy') or 'scale_free'
        if policy == 'every_frame':
            options += ['--every', '1']
        elif policy == 'every_nth':
            options += ['--every', str(get('every_n') or 10)]
        else:
            options += ['--keyframe-policy', policy]
            for param, option in (('min_translation', '--min-translation'), ('min_rotation_deg', '--min-rotation'),
                                  ('keyframe_overlap', '--keyframe-overlap'),
                                  ('keyframe_parallax_deg', '--keyframe-parallax-deg')):
                if get(param) is not None:
                    options += [option, repr(float(get(param)))]
        for param, option in (('k', '--k'), ('completion', '--completion'),
                              ('min_covisible_points', '--min-covisible-points'),
                              ('min_covisible_ratio', '--min-covisible-ratio'),
                              ('max_view_angle_deg', '--max-view-angle'), ('grid', '--grid')):
            value = get(param)
            if value is not None:
                options += [option, repr(value) if isinstance(value, float) else str(value)]
        if get('occlusion_test') is False:
            options.append('--no-occlusion')
        if get('revisit_registration') is not None:
            options += ['--revisit-registration', 'true' if get('revisit_registration') else 'false']
        return options

    @classmethod
    def wait_for_subscribers(cls):
        """rosbag play must not start before every node listens, or the first frames are lost."""
        wanted = {}
        for node in cls.nodes:
            topics = ['/camera/rgb/image_color', '/camera/rgb/camera_info', '/camera/depth/image']
            topics.append('/tf' if rospy.get_param(node + '/pose_source', 'tf') == 'tf' else '/camera/pose')
            wanted[node] = topics
        wait_for_subscribers(wanted, cls.timeout)

    @classmethod
    def wait_until_processed(cls):
        """Waits (bounded) until every node has handled every frame of the bag: offered or
        dropped, as its ~statistics count them. A frame lost before the node shows as a count
        that stops short, which check_statistics reports."""
        from view_selection.msg import InputStatistics
        for node in cls.nodes:
            deadline = time.time() + cls.timeout
            while True:
                stats = rospy.wait_for_message(node + '/statistics', InputStatistics,
                                               timeout=cls.timeout)
                if stats.frames_offered + stats.frames_dropped >= cls.frames:
                    break
                if time.time() > deadline:
                    rospy.logwarn('%s handled %d of %d frames within %.0f s', node,
                                  stats.frames_offered + stats.frames_dropped, cls.frames,
                                  cls.timeout)
                    break  # the checks below say what is missing
                time.sleep(0.1)

    @classmethod
    def call(cls, node, name, srv_type, *args):
        """A service call that fails the test instead of hanging when the node does not answer."""
        return call(node + '/' + name, srv_type, args[0] if args else None, timeout=cls.timeout)

    # ------------------------------------------------------------------------------------------
    def setUp(self):
        if self.skip_reason:
            rospy.logwarn('replay test skipped: %s', self.skip_reason)
            self.skipTest(self.skip_reason)

    def assertClose(self, actual, expected, tolerance, what):
        if tolerance == 0.0:
            self.assertEqual(actual, expected, what)
        else:
            self.assertLessEqual(abs(actual - expected), tolerance * max(1.0, abs(expected)),
                                 '%s: %r vs %r' % (what, actual, expected))

    def check_selection(self, node, tolerance):
        answer = self.call(node, 'get_selection', GetSelection)
        self.assertTrue(answer.success, '%s/get_selection: %s' % (node, answer.message))
        s, e = answer.selection, self.expected
        n = len(e['keyframes'])
        self.assertGreater(n, 2, 'select_views found too few keyframes for a meaningful test')
        # No keyframe lost, none extra: the same keyframes, by stamp, in the same order.
        self.assertEqual([msg_stamp_ns(k.stamp) for k in s.keyframes], [stamp_ns(k['stamp']) for k in e['keyframes']],
                         '%s: keyframe stamps differ from select_views\'s' % node)
        self.assertEqual(s.k, e['params']['k'])
        self.assertEqual(s.completion, e['params']['completion'])
        for i, (k, x) in enumerate(zip(s.keyframes, e['keyframes'])):
            what = '%s keyframe %d' % (node, i)
            self.assertEqual(k.id, i, what)
            self.assertEqual(k.num_points, x['num_points'], what + ' sample points')
            self.assertEqual(k.revisit_of, x.get('revisit_of', -1), what + ' revisit_of')
            p, q = k.pose.position, k.pose.orientation
            for a, b, c in zip((p.x, p.y, p.z), x['position'], 'xyz'):
                self.assertClose(a, b, tolerance, what + ' position ' + c)
            for a, b, c in zip((q.x, q.y, q.z, q.w), x['orientation_xyzw'], 'xyzw'):
                self.assertClose(a, b, tolerance, what + ' orientation ' + c)
        matrix = dense_error_resistance(e)
        self.assertEqual(len(s.next_view_sets), n)
        for i, v in enumerate(s.next_view_sets):
            what = '%s C_%d' % (node, i)
            self.assertEqual(v.view, i, what)
            self.assertEqual(list(v.next_views), e['next_views'][i], what)
            final = e['final_next_views'][i]
            self.assertEqual(list(v.next_views) + list(v.completed_views), final, what + ' after completion')
            values = list(v.error_resistance) + list(v.completed_error_resistance)
            for j, value in zip(final, values):
                self.assertIsNotNone(matrix[i][j], what)
                self.assertClose(value, matrix[i][j], tolerance, '%s E[%d][%d]' % (node, i, j))
        self.assertEqual(s.start_view, -1 if e['start_view'] is None else e['start_view'], node + ' start view')
        initial = e.get('initial_pair')
        self.assertEqual(list(s.initial_pair), list(initial) if initial else [], node + ' initial pair')
        self.assertEqual(list(s.order), e['order'], node + ' order')
        self.assertEqual([(c.view, c.added_to) for c in s.completed],
                         [(c['view'], c['added_to']) for c in e['completed']], node + ' completed')
        self.assertEqual(list(s.isolated), e['isolated'], node + ' isolated')
        self.assertEqual([[p.first, p.second] for p in s.pairs], e['pairs'], node + ' pairs')
        finite = sum(1 for i, row in enumerate(matrix) for j, v in enumerate(row) if i != j and v is not None)
        self.assertEqual(s.finite_entries, finite, node + ' finite entries')

    def check_statistics(self, node):
        """Every frame of the bag reached the node and none was dropped."""
        try:
            from view_selection.msg import InputStatistics
        except ImportError:
            self.fail('view_selection/InputStatistics is not built')
        stats = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=self.timeout)
        reasons = dict(zip(stats.drop_reasons, stats.drop_counts))
        self.assertEqual(stats.frames_dropped, 0, '%s dropped frames: %s (last: %s)' % (node, reasons, stats.last_error))
        self.assertEqual(stats.frames_received, self.frames, node + ': frames received')
        self.assertEqual(stats.frames_offered, self.frames, node + ': frames offered to the keyframe policy')
        self.assertEqual(stats.keyframes, len(self.expected['keyframes']), node + ': keyframes')

    def check_export(self, node):
        """~export writes pairs.txt with the same pairs, in the same order, as select_views."""
        directory = os.path.join(self.tmp, 'export_' + node.strip('/').replace('/', '_'))
        answer = self.call(node, 'export', Export, ExportRequest(directory=directory))
        self.assertTrue(answer.success, '%s/export: %s' % (node, answer.message))
        with open(answer.pairs_txt) as f:
            pairs_txt = f.read()
        with open(answer.selection_json) as f:
            exported = json.load(f)
        self.assertEqual(exported['pairs'], self.expected['pairs'], node + ' exported selection.json pairs')
        # Image names: select_views uses the TUM file names, the node names images by stamp; both
        # name each keyframe once, so the files must say the same once names are mapped to stamps.
        def by_stamp(text, selection):
            names = {k['image']: stamp_ns(k['stamp']) for k in selection['keyframes']}
            self.assertEqual(len(set(names.values())), len(selection['keyframes']), 'image names are not unique')
            lines = []
            for line in text.splitlines():
                a, b = line.split()
                self.assertIn(a, names, 'pairs.txt names an image that is no keyframe: ' + a)
                self.assertIn(b, names, 'pairs.txt names an image that is no keyframe: ' + b)
                lines.append((names[a], names[b]))
            return lines
        self.assertEqual(by_stamp(pairs_txt, exported), by_stamp(self.expected_pairs_txt, self.expected),
                         node + ' pairs.txt differs from select_views\'s')
        self.assertEqual(len(pairs_txt.splitlines()), len(self.expected['pairs']))
        if rospy.get_param(node + '/save_keyframe_images', False):
            self.assertEqual(answer.images_written, len(self.expected['keyframes']), node + ' images written')
            for k in exported['keyframes']:
                self.assertTrue(os.path.isfile(os.path.join(directory, exported['params'].get('image_path', ''),
                                                            k['image'])), node + ' image ' + k['image'])

    def test_2_bag_has_the_tum_layout(self):
        """tum_to_bag: topics, types, encodings, frame ids, stamps and pixel values of the TUM folder."""
        import cv2
        import numpy
        import rosbag

        def read_list(name):
            entries = []
            with open(os.path.join(self.source, name)) as f:
                for line in f:
                    if line.strip() and not line.startswith('#'):
                        stamp, path = line.split()
                        entries.append((float(stamp), path))
            return entries
        rgb, depth = read_list('rgb.txt'), read_list('depth.txt')
        # The kitchen and the synthetic sequence have one depth image per colour image, same stamps.
        self.assertEqual([s for s, _ in rgb], [s for s, _ in depth], 'this check assumes aligned lists')
        frames = list(zip(rgb, depth))[:self.max_frames]
        expected_types = {'/camera/rgb/image_color': 'sensor_msgs/Image', '/camera/rgb/camera_info': 'sensor_msgs/CameraInfo',
                          '/camera/depth/image': 'sensor_msgs/Image', '/camera/depth/camera_info': 'sensor_msgs/CameraInfo',
                          '/tf': 'tf2_msgs/TFMessage', '/camera/pose': 'geometry_msgs/PoseStamped'}
        with rosbag.Bag(self.bag) as bag:
            info = bag.get_type_and_topic_info().topics
            self.assertEqual({t: i.msg_type for t, i in info.items()}, expected_types)
            for topic in expected_types:
                self.assertEqual(info[topic].message_count, len(frames), topic)
            seen = {t: [] for t in expected_types}
            checked = 0
            for topic, msg, t in bag.read_messages():
                header = msg.transforms[0].header if topic == '/tf' else msg.header
                self.assertEqual(msg_stamp_ns(t), msg_stamp_ns(header.stamp), topic + ': bag time is the stamp')
                seen[topic].append(msg_stamp_ns(header.stamp))
                if topic == '/tf':
                    self.assertEqual((header.frame_id, msg.transforms[0].child_frame_id),
                                     ('/world', '/openni_rgb_optical_frame'))
                elif topic == '/camera/pose':
                    self.assertEqual(header.frame_id, '/world')
                else:
                    self.assertEqual(header.frame_id, '/openni_rgb_optical_frame', topic)
                index = len(seen[topic]) - 1
                if topic == '/camera/rgb/image_color' and index < 3:
                    self.assertEqual(msg.encoding, 'rgb8')
                    image = numpy.frombuffer(msg.data, numpy.uint8).reshape(msg.height, msg.width, 3)
                    bgr = cv2.imread(os.path.join(self.source, frames[index][0][1]), cv2.IMREAD_COLOR)
                    self.assertTrue(numpy.array_equal(image, bgr[:, :, ::-1]), 'rgb8 pixels of frame %d' % index)
                    checked += 1
                if topic == '/camera/depth/image' and index < 3:
                    self.assertEqual(msg.encoding, '32FC1')
                    image = numpy.frombuffer(msg.data, numpy.float32).reshape(msg.height, msg.width)
                    png = cv2.imread(os.path.join(self.source, frames[index][1][1]), cv2.IMREAD_ANYDEPTH)
                    valid = png > 0
                    self.assertTrue(numpy.all(numpy.isnan(image[~valid])), 'missing depth is NaN')
                    self.assertTrue(numpy.array_equal(image[valid], (png[valid] * (1.0 / 5000.0)).astype(numpy.float32)),
                                    'depth in metres of frame %d' % index)
                    checked += 1
            self.assertEqual(checked, 6)
        stamps = [stamp_ns(s) for (s, _), _ in frames]
        for topic in expected_types:
            self.assertEqual(seen[topic], stamps, topic + ' stamps are the TUM stamps, in order')

    def test_3_tum_to_bag_reports_bad_input(self):
        tool = find_tool('tum_to_bag')
        missing = os.path.join(self.tmp, 'no_such_folder')
        cases = [([], 2, '--dataset DIR is required'),
                 (['--dataset', self.source], 2, '--out BAG is required'),
                 (['--dataset', self.source, '--out', os.path.join(self.tmp, 'x.bag'), '--every', '0'], 2, '--every'),
                 (['--dataset', missing, '--out', os.path.join(self.tmp, 'y.bag')], 1, missing)]
        for args, code, text in cases:
            done = subprocess.run([tool] + args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=60,
                                  universal_newlines=True)
            self.assertEqual(done.returncode, code, '%s: %s' % (args, done.stdout))
            self.assertIn(text, done.stdout, args)
        self.assertFalse(os.path.exists(os.path.join(self.tmp, 'y.bag')), 'no bag is left after an error')

    def test_4_drifted_revisits_are_recognised_from_the_images(self):
        """With ~drifted_revisit: the drifted revisit adds (nearly) no keyframe where the rule of
        the poses alone adds many, and the node counts revisits recognised from the images."""
        if not self.revisit:
            self.skipTest('no ~drifted_revisit')
        from view_selection.msg import InputStatistics
        later, beyond = self.revisit_stamp - 1e-6, self.new_ground_stamp - 1e-6

        def revisiting(keyframes):
            return [k for k in keyframes if later < k['stamp'] < beyond]
        registered = revisiting(self.expected['keyframes'])
        alone = revisiting(self.expected_poses_alone['keyframes'])
        first = len([k for k in self.expected['keyframes'] if k['stamp'] <= later])
        rospy.loginfo('keyframes of the first pass: %d; of the drifted revisit of its ground: %d, with the poses '
                      'alone %d', first, len(registered), len(alone))
        self.assertGreaterEqual(len(alone), first // 4, 'the drift places the revisit off the first pass')
        self.assertLessEqual(len(registered), 2, 'the revisit is recognised from the images')
        # Where the revisit goes on to new ground, the keyframe made there names the first-pass
        # keyframe it was revisiting (check_selection: the node's are select_views's): the pair
        # across the drift that colmap_bridge's loop pairs match.
        new = [k for k in self.expected['keyframes'] if k['stamp'] > beyond]
        self.assertTrue(new, 'the revisit makes keyframes on new ground')
        links = [k for k in self.expected['keyframes'] if k.get('revisit_of', -1) >= 0]
        rospy.loginfo('keyframes naming the keyframe they revisit: %s',
                      [(k['id'], k['revisit_of']) for k in links])
        self.assertTrue(links, 'no keyframe names a revisit')
        self.assertTrue(all(k['stamp'] > later and k['revisit_of'] < first for k in links), links)
        self.assertGreaterEqual(new[0].get('revisit_of', -1), 0, 'the first keyframe past the first pass')
        for node in self.nodes:
            stats = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=self.timeout)
            # Each frame the poses alone made a keyframe of is one the registration has to
            # recognise (measured: 62 recognised where the poses alone made 30 keyframes).
            self.assertGreaterEqual(stats.revisits_registered, max(1, len(alone) // 2),
                                    node + ': revisits recognised from the image')
            self.assertGreaterEqual(stats.revisits, stats.revisits_registered, node)

    # One test method a node, so that a failure names the pose source.
    def test_0_topic_pose_source(self):
        self._check_node(0)

    def test_1_tf_pose_source(self):
        self._check_node(1)

    def _check_node(self, index):
        if index >= len(self.nodes):
            self.skipTest('no node %d in ~nodes' % index)
        node, tolerance = self.nodes[index], self.tolerances[index]
        self.check_selection(node, tolerance)
        self.check_statistics(node)
        self.check_export(node)


if __name__ == '__main__':
    rospy.init_node('replay_tester')
    rostest.rosrun(PKG, 'replay', Replay, sys.argv)
