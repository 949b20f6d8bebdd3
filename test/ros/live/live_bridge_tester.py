#!/usr/bin/env python3
"""The live hand-off (issue 18), for real: the built-in synthetic sequence as a bag (tum_to_bag),
played with rosbag play through view_selection_node at its shipped defaults, beside two
colmap_bridge processes running the real COLMAP 3.8:

  - bridge A is SIGKILLed once it has matched something, and started again on its project;
  - bridge B runs uninterrupted on a project that shares A's images folder;
  - bridge C too, with a ~max_backlog of 0, so that every pair waits for the finish.

Two pair-stream consumers of the tester's own follow ~pairs: one drops every third message and
catches up through ~get_pairs, one joins halfway. After the bag: both consumers hold exactly the
node's final pairs; each bridge's ~finish builds the known-pose model; A's database equals B's
(features, matches, verified pairs); nothing was extracted or matched twice (the ledger); every
final pair is in the database; every keyframe is in the model at its node pose within 1e-6
(sparse/unrefined), and in the refined model (sparse/0) within the refinement's precision.

Bridge B's model on ROS (issue 36), watched from before the bag plays: the last ~points message
is sparse/0's points (count and coordinates, float precision), coloured from the keyframe images
at their keypoints, in the node's world frame; ~cameras has one frustum a keyframe at sparse/0's
poses, which are the node's (the model's world is the node's); a subscriber that joins after the
finish gets the same latched messages.
"""
import json
import math
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
import unittest

import cv2
import numpy as np
import rospy
import rostest
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from view_selection import geometry
from view_selection.colmap.model import read_model
from view_selection.msg import PairChanges
from view_selection.srv import ExportRequest, Export, GetPairs, GetPairsRequest, GetSelection

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_replay import bridge_report_after, run  # noqa: E402
from vs_robust import NodeProcess, Statistics, call, find_tool, wait_until  # noqa: E402

NODE = '/live_vs'
TOPICS = {'image': '/camera/rgb/image_color', 'camera_info': '/camera/rgb/camera_info',
          'depth': '/camera/depth/image', 'pose': '/camera/pose'}



class Consumer:
    """A pair-stream consumer: applies ~pairs in sequence; on a gap (a message it missed, or one
    it was told to drop) it calls ~get_pairs with the last sequence it applied, and it polls
    ~get_pairs now and then (the message it missed may be the last one)."""

    def __init__(self, node, drop_every=0):
        self.node, self.drop_every = node, drop_every
        self.lock = threading.Lock()
        self.pairs, self.sequence, self.received, self.dropped, self.catch_ups = set(), 0, 0, 0, 0
        self.catch_up()
        self.sub = rospy.Subscriber(node + '/pairs', PairChanges, self.on, queue_size=1000)

    def apply(self, m):
        if m.full:
            self.pairs = set()
        for p in m.removed:
            self.pairs.discard((p.first, p.second))
        for p in m.added:
            self.pairs.add((p.first, p.second))
        self.sequence = m.sequence

    def on(self, m):
        with self.lock:
            self.received += 1
            if self.drop_every and self.received % self.drop_every == 0:
                self.dropped += 1
                return
            if m.full or m.sequence == self.sequence + 1:
                self.apply(m)
                return
            if m.sequence <= self.sequence:
                return
        self.catch_up()

    def catch_up(self):
        with self.lock:
            since = self.sequence
        res = call(self.node + '/get_pairs', GetPairs, GetPairsRequest(since=since), 30.0)
        with self.lock:
            self.catch_ups += 1
            for m in res.changes:
                if m.full or m.sequence > self.sequence:
                    self.apply(m)

    def current(self):
        with self.lock:
            return set(self.pairs)


class ModelListener:
    """The last ~points and ~cameras messages of a bridge, and how many came."""

    def __init__(self, bridge):
        self.lock = threading.Lock()
        self.points, self.cameras, self.sizes = None, None, []
        self.subs = [rospy.Subscriber(bridge + '/points', PointCloud2, self.on_points, queue_size=5),
                     rospy.Subscriber(bridge + '/cameras', MarkerArray, self.on_cameras, queue_size=5)]

    def on_points(self, m):
        with self.lock:
            self.points = m
            self.sizes.append(m.width)

    def on_cameras(self, m):
        with self.lock:
            self.cameras = m

    def close(self):
        for sub in self.subs:
            sub.unregister()


def cloud_rows(msg):
    """x, y, z (float32 -> float64) and rgb (uint32) of a PointCloud2 as colmap_bridge packs it."""
    rows = np.frombuffer(msg.data, np.dtype('<f4')).reshape(-1, 4)
    return rows[:, :3].astype(np.float64), rows.view(np.dtype('<u4'))[:, 3]


def database_content(path):
    """What a COLMAP database holds, by image name: keypoints, descriptors, raw matches and the
    verified pairs."""
    con = sqlite3.connect(path)
    try:
        names = {iid: name for iid, name in con.execute('SELECT image_id, name FROM images')}
        keypoints = {names[i]: (r, bytes(d or b'')) for i, r, d in con.execute('SELECT image_id, rows, data FROM keypoints')}
        descriptors = {names[i]: bytes(d or b'') for i, d in con.execute('SELECT image_id, data FROM descriptors')}

        def by_pair(table):
            out = {}
            for pid, rows, data in con.execute('SELECT pair_id, rows, data FROM %s' % table):
                a, b = pid // 2147483647, pid % 2147483647
                out[tuple(sorted((names[a], names[b])))] = (rows, bytes(data or b''))
            return out
        return {'images': sorted(names.values()), 'keypoints': keypoints, 'descriptors': descriptors,
                'matches': by_pair('matches'), 'verified': by_pair('two_view_geometries')}
    finally:
        con.close()


def quaternion_matrix(q):
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]


def model_poses(colmap, model, work):
    os.makedirs(work, exist_ok=True)
    run([colmap, 'model_converter', '--input_path', model, '--output_path', work, '--output_type', 'TXT'], 120,
        'model_converter')
    poses = {}
    with open(os.path.join(work, 'images.txt')) as f:
        lines = [l for l in f if not l.startswith('#')]
    for q in range(0, len(lines), 2):
        parts = lines[q].split()
        if len(parts) >= 10:
            poses[parts[9]] = [float(v) for v in parts[1:8]]
    return poses


def expected_pose(k):
    """COLMAP's (qw qx qy qz tx ty tz) of a node keyframe (camera-to-world pose)."""
    o, p = k.pose.orientation, k.pose.position
    w, x, y, z = o.w, o.x, o.y, o.z
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    r = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    c = (p.x, p.y, p.z)
    t = [-sum(r[j][i] * c[j] for j in range(3)) for i in range(3)]  # -R^T c
    q = (w, -x, -y, -z)  # the inverse rotation
    if q[0] < 0:
        q = tuple(-v for v in q)
    return list(q) + t


class LiveBridge(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.timeout = float(rospy.get_param('~timeout', 120.0))
        cls.frames = int(rospy.get_param('~frames', 90))
        cls.colmap = shutil.which('colmap')
        assert cls.colmap, 'COLMAP is not installed (scripts/install_deps colmap)'
        bridge = find_tool('colmap_bridge')
        assert bridge, 'colmap_bridge is not built'
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_live_')
        source = os.path.join(cls.tmp, 'synthetic')
        run([find_tool('generate_sequence'), '--out', source, '--frames', str(cls.frames), '--width', '320',
             '--height', '240', '--quiet'], 600, 'generate_sequence')
        cls.bag = os.path.join(cls.tmp, 'live.bag')
        run([find_tool('tum_to_bag'), '--dataset', source, '--out', cls.bag, '--quiet'], 600, 'tum_to_bag')

        cls.a, cls.b = os.path.join(cls.tmp, 'project_a'), os.path.join(cls.tmp, 'project_b')
        cls.c = os.path.join(cls.tmp, 'project_c')
        os.makedirs(os.path.join(cls.a, 'images'))
        for other in (cls.b, cls.c):
            os.makedirs(other)
            os.symlink(os.path.join(cls.a, 'images'), os.path.join(other, 'images'))  # the node writes one folder

        # The node at its shipped defaults, poses from the bag's /camera/pose.
        cls.node = NodeProcess(NODE, {'pose_source': 'topic'}, remaps=TOPICS).start()
        cls.node.wait_for_services(cls.timeout)
        cls.statistics = Statistics(NODE)
        cls.bridge_a = NodeProcess('/bridge_a', {'project': cls.a, 'node': NODE}, binary=bridge)
        cls.bridge_b = NodeProcess('/bridge_b', {'project': cls.b, 'node': NODE}, binary=bridge)
        # Not the default (2000): this short sequence never has that many pairs waiting, and the
        # finish must match a backlog beyond ~max_backlog whole (issue 34). With 0 every pair
        # waits for the finish.
        cls.bridge_c = NodeProcess('/bridge_c', {'project': cls.c, 'node': NODE, 'max_backlog': 0}, binary=bridge)
        cls.bridges = (cls.bridge_a, cls.bridge_b, cls.bridge_c)
        for b in cls.bridges:
            b.start()
        for b in cls.bridges:
            cls.wait_service(b.name + '/finish', b)
        cls.dropping = Consumer(NODE, drop_every=3)
        cls.model_b = ModelListener(cls.bridge_b.name)  # from the start: every message of the run

        player = subprocess.Popen(['rosbag', 'play', '-q', '-d', '1', cls.bag], stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, universal_newlines=True)
        cls.killed_after = None
        cls.late = None
        try:
            start = time.time()
            duration = cls.frames / 30.0
            ledger = os.path.join(cls.a, 'ledger.txt')
            while player.poll() is None and time.time() - start < 60 + 4 * duration:
                if cls.late is None and time.time() - start > 1.0 + duration / 2:
                    cls.late = Consumer(NODE)  # joins halfway
                if cls.killed_after is None and os.path.exists(ledger) and ' matched ' in open(ledger).read():
                    cls.bridge_a.kill()  # SIGKILL: no chance to clean up
                    cls.killed_after = open(ledger).read().count(' matched ')
                    cls.bridge_a.start()
                time.sleep(0.05)
            assert player.poll() is not None, 'rosbag play did not end'
        finally:
            if player.poll() is None:
                player.kill()
        if cls.late is None:
            cls.late = Consumer(NODE)
        # The node flushes its pending pairs once no frame came for ~pair_flush_idle.
        # The node flushes its pending pairs once no frame came for ~pair_flush_idle.
        state = {}

        def converged():
            for consumer in (cls.late, cls.dropping):
                consumer.catch_up()  # a consumer polls ~get_pairs: the last message may be the one it missed
            selection = call(NODE + '/get_selection', GetSelection, None, 30.0).selection
            cls.final = {(p.first, p.second) for p in selection.pairs}
            state['last'] = 'final %d pairs, late consumer %d (%d missing), dropping %d (%d missing)' % (
                len(cls.final), len(cls.late.current()), len(cls.final - cls.late.current()),
                len(cls.dropping.current()), len(cls.final - cls.dropping.current()))
            return cls.late.current() == cls.final and cls.dropping.current() == cls.final
        try:
            wait_until(converged, cls.timeout, 'the consumers hold the final pairs', period=0.5)
        except AssertionError as e:
            raise AssertionError('%s: %s' % (e, state.get('last')))
        if cls.killed_after is None:  # matched nothing while playing (a slow machine): kill now
            cls.bridge_a.kill()
            cls.killed_after = 0
            cls.bridge_a.start()
            cls.wait_service(cls.bridge_a.name + '/finish', cls.bridge_a)
        cls.selection = call(NODE + '/get_selection', GetSelection, None, 30.0).selection
        cls.finish_a = cls.finish(cls.bridge_a.name)
        cls.finish_b = cls.finish(cls.bridge_b.name)
        cls.finish_c = cls.finish(cls.bridge_c.name)
        for project in (cls.a, cls.b, cls.c):  # a finish its budget cut short (a loaded machine) is refined after
            wait_until(bridge_report_after(project, 0.0), cls.timeout, 'the refinement after the finish in ' + project,
                       period=0.2)
        # The finished model goes out after the finish (at most ~publish_period later): the last
        # message is sparse/0's points once one is.
        cls.sparse_b = read_model(os.path.join(cls.b, 'sparse', '0'))
        want = np.array([cls.sparse_b.points[i].xyz for i in sorted(cls.sparse_b.points)])
        seen = {}

        def published():
            with cls.model_b.lock:
                msg = cls.model_b.points
            if msg is None or cls.model_b.cameras is None or msg.width != len(want) or seen.get('last') is msg:
                return False
            seen['last'] = msg
            xyz, _ = cloud_rows(msg)
            return all(np.min(np.sum((want - x) ** 2, axis=1)) < 1e-10 for x in xyz)
        try:
            wait_until(published, 60.0, 'bridge B publishes its finished model', period=0.1)
        except AssertionError as e:
            cls.model_error = '%s (point counts of its messages: %s)' % (e, cls.model_b.sizes)
        else:
            cls.model_error = None

    @classmethod
    def finish(cls, bridge):
        """~finish, asked again while the bridge's own finish (~finish_after_idle, after the bag)
        is running: it waits for that one, then finishes again (before, it answered 'a finish is
        running', which the loop below still tolerates). On the loaded machine bridge_b's idle
        finish began 4.5-12 s after the last keyframe, while bridge_a's ~finish ran."""
        answer = {}

        def answered():
            answer['r'] = call(bridge + '/finish', Trigger, None, 900.0)
            return answer['r'].success or answer['r'].message != 'a finish is running'
        wait_until(answered, cls.timeout, bridge + '/finish while its own finish runs', period=0.5)
        return answer['r']

    @classmethod
    def wait_service(cls, name, process):
        try:
            rospy.wait_for_service(name, timeout=cls.timeout)
        except rospy.ROSException:
            raise AssertionError('%s not advertised; output:\n%s' % (name, process.output()[-3000:]))

    @classmethod
    def tearDownClass(cls):
        for p in ('bridge_a', 'bridge_b', 'bridge_c', 'node'):
            proc = getattr(cls, p, None)
            if proc:
                try:
                    proc.stop(60)
                except AssertionError:
                    pass
        if os.environ.get('VIEW_SELECTION_KEEP_TEST_OUTPUT'):
            rospy.loginfo('live test output kept in %s', cls.tmp)
        else:
            shutil.rmtree(cls.tmp, ignore_errors=True)

    def names(self):
        return {k.id: k.image_name for k in self.selection.keyframes}

    def test_finish_succeeds(self):
        self.assertTrue(self.finish_a.success, self.finish_a.message + self.bridge_a.output()[-3000:])
        self.assertTrue(self.finish_b.success, self.finish_b.message + self.bridge_b.output()[-3000:])
        self.assertGreaterEqual(len(self.selection.keyframes), 5)

    def test_database_holds_every_final_pair(self):
        names = self.names()
        final = {tuple(sorted((names[a], names[b]))) for a, b in self.final}
        self.assertTrue(final)
        for project in (self.a, self.b):
            content = database_content(os.path.join(project, 'database.db'))
            self.assertEqual(set(), final - set(content['verified']), project)
            self.assertEqual(set(), set(names.values()) - set(content['descriptors']), project)

    def test_a_backlog_beyond_max_backlog_is_matched_whole_at_the_finish(self):
        self.assertTrue(self.finish_c.success, self.finish_c.message + self.bridge_c.output()[-3000:])
        report = json.load(open(os.path.join(self.c, 'report.json')))
        self.assertGreater(report['deferred_to_finish'], 0, 'the backlog never went beyond ~max_backlog')
        self.assertEqual([], report['pairs_lost'])
        self.assertEqual(len(self.final), report['final_pairs'])
        self.assertEqual(report['final_pairs'], report['final_pairs_matched'])
        names = self.names()
        final = {tuple(sorted((names[a], names[b]))) for a, b in self.final}
        self.assertEqual(set(), final - set(database_content(os.path.join(self.c, 'database.db'))['matches']))

    def test_model_has_every_keyframe_at_its_pose(self):
        """sparse/unrefined: every keyframe at its node pose. sparse/0, the refined model (issue
        29): every keyframe, and since this node's poses are exact, corrections within what the
        refinement's own precision allows: measured here (two runs, the same figures) at most
        6.5 mm and 0.71 deg, median 3.4 mm and 0.60 deg; the limits are 1.5 times those (the
        largest rotation's 1 deg, 1.4 times)."""
        poses = model_poses(self.colmap, os.path.join(self.a, 'sparse', 'unrefined'), os.path.join(self.tmp, 'model_txt'))
        refined = model_poses(self.colmap, os.path.join(self.a, 'sparse', '0'), os.path.join(self.tmp, 'refined_txt'))
        for k in self.selection.keyframes:
            self.assertIn(k.image_name, poses, 'keyframe %d is not in the model' % k.id)
            self.assertIn(k.image_name, refined, 'keyframe %d is not in the refined model' % k.id)
            want, got = expected_pose(k), poses[k.image_name]
            for q in range(7):
                self.assertAlmostEqual(want[q], got[q], delta=1e-6, msg='keyframe %d: %s vs %s' % (k.id, want, got))
        report = json.load(open(os.path.join(self.a, 'report.json')))
        self.assertEqual(len(self.selection.keyframes), report['registered'])
        self.assertGreater(report['points'], 100)
        self.assertEqual(len(self.final), report['final_pairs_matched'])
        r = report['refinement']
        self.assertTrue(r['refined'], r)
        self.assertEqual({k.image_name for k in self.selection.keyframes}, {k['name'] for k in r['keyframes']})
        rospy.loginfo('refinement with exact poses: the largest correction %.5f m, %.4f deg; median %.5f m, %.4f deg',
                      max(k['translation'] for k in r['keyframes']), max(k['rotation_deg'] for k in r['keyframes']),
                      r['translation_median'], r['rotation_median_deg'])
        for k in r['keyframes']:
            self.assertLess(k['translation'], 1.5 * 0.0065, k)
            self.assertLess(k['rotation_deg'], 1.0, k)  # 1.4 times the measured 0.71
        self.assertLess(r['translation_median'], 1.5 * 0.0034, r['translation_median'])
        self.assertLess(r['rotation_median_deg'], 1.5 * 0.60, r['rotation_median_deg'])

    def test_offline_gives_the_same_model(self):
        """colmap_from_selection --model known_poses on the node's ~export of the same keyframes
        lays out the same project and builds the same model as the bridge did online."""
        export = os.path.join(self.tmp, 'export')
        answer = call(NODE + '/export', Export, ExportRequest(directory=export), 60.0)
        self.assertTrue(answer.success, answer.message)
        offline = os.path.join(self.tmp, 'offline')
        run([find_tool('colmap_from_selection'), export, '--model', 'known_poses', '--image-path',
             os.path.join(self.a, 'images'), '--out', offline], 900, 'colmap_from_selection')
        for part in ('database.db', 'images', 'report.json', os.path.join('sparse', '0')):
            self.assertTrue(os.path.exists(os.path.join(offline, part)), part)
        online_poses = model_poses(self.colmap, os.path.join(self.a, 'sparse', 'unrefined'), os.path.join(self.tmp, 'on'))
        offline_poses = model_poses(self.colmap, os.path.join(offline, 'sparse', 'unrefined'),
                                    os.path.join(self.tmp, 'off'))
        self.assertEqual(sorted(online_poses), sorted(offline_poses))
        for name in online_poses:
            for a, b in zip(online_poses[name], offline_poses[name]):
                self.assertAlmostEqual(a, b, delta=1e-9, msg=name)
        # The refined models: the same keyframes, centres within 3 mm RMS (the refinement's own
        # precision here, 1-3 mm of ATE; the databases differ by the pairs the bridge matched and
        # the node took back, so the points differ a little; and the bridge refined as the
        # recording went on (refinement/local.py): what the finish held was refined by earlier
        # runs with fewer pairs. Measured 0.1 mm when the finish refined everything, 2.04 mm since).
        on = model_poses(self.colmap, os.path.join(self.a, 'sparse', '0'), os.path.join(self.tmp, 'on_refined'))
        off = model_poses(self.colmap, os.path.join(offline, 'sparse', '0'), os.path.join(self.tmp, 'off_refined'))
        self.assertEqual(sorted(on), sorted(off))
        centre = lambda p: -np.array(quaternion_matrix(p[:4])).T @ np.array(p[4:7])
        rms = math.sqrt(sum(float(np.sum((centre(on[n]) - centre(off[n])) ** 2)) for n in on) / len(on))
        rospy.loginfo('online vs offline refined keyframes: RMS %.5f m', rms)
        online = json.load(open(os.path.join(self.a, 'report.json')))
        off = json.load(open(os.path.join(offline, 'report.json')))
        if online['refinement']['status'] == 'out_of_time':
            # The finish's refinement stopped at ~refine_max_seconds on a loaded machine: it is
            # between the unrefined model and the offline one, which has no budget.
            self.assertLess(rms, 0.002 + off['refinement']['translation_max'], online['refinement']['message'])
        else:
            self.assertLess(rms, 0.003)
        self.assertEqual(online['registered'], off['registered'])
        self.assertEqual(online['final_pairs'], off['final_pairs'])
        # The same pairs matched; points within COLMAP's run-to-run SIFT differences.
        self.assertLessEqual(abs(online['points'] - off['points']), 0.03 * online['points'] + 5,
                             (online['points'], off['points']))

    def test_points_are_the_model(self):
        """~points: sparse/0's points, the same coordinates as float32 (the same multiset: the
        model has points at identical coordinates, from SIFT keypoints that OpenCV gives twice at
        one place with two orientations), each coloured as a keyframe image that sees it is at its
        keypoint, in the node's world frame."""
        self.assertIsNone(self.model_error, 'messages %s' % self.model_b.sizes)
        msg = self.model_b.points
        rospy.loginfo('bridge B ~points: %d messages, points %s', len(self.model_b.sizes), self.model_b.sizes)
        self.assertTrue(self.selection.header.frame_id)
        self.assertEqual(self.selection.header.frame_id, msg.header.frame_id)
        self.assertEqual(['x', 'y', 'z', 'rgb'], [f.name for f in msg.fields])
        self.assertEqual([0, 4, 8, 12], [f.offset for f in msg.fields])
        self.assertEqual((1, 16, len(msg.data)), (msg.height, msg.point_step, 16 * msg.width))
        xyz, rgb = cloud_rows(msg)
        points = [self.sparse_b.points[i] for i in sorted(self.sparse_b.points)]
        want = np.array([p.xyz for p in points])
        self.assertGreater(len(want), 100)
        self.assertEqual(len(want), len(xyz))
        published = xyz.astype(np.float32)
        model32 = want.astype(np.float32)
        np.testing.assert_array_equal(published[np.lexsort(published.T)], model32[np.lexsort(model32.T)])
        rows = {}  # coordinates -> published rows
        for row, x in enumerate(published):
            rows.setdefault(x.tobytes(), []).append(row)
        same = {}  # coordinates -> model points
        for p, x in zip(points, model32):
            same.setdefault(x.tobytes(), []).append(p)
        images, read = self.sparse_b.images, {}

        def colour(iid, idx):
            im = images[int(iid)]
            if im.name not in read:
                read[im.name] = cv2.imread(os.path.join(self.a, 'images', im.name), cv2.IMREAD_COLOR)
            x, y = (int(math.floor(v)) for v in im.xys[int(idx)])
            b, g, r = (int(v) for v in read[im.name][y, x])
            return (r << 16) | (g << 8) | b
        for q in range(0, len(points), max(1, len(points) // 200)):  # 200 of them: the colour
            key = model32[q].tobytes()
            seen = {colour(iid, idx) for p in same[key] for iid, idx in zip(p.image_ids, p.point2D_idxs)}
            for row in rows[key]:
                self.assertIn(int(rgb[row]), seen, 'point %d' % points[q].id)

    def test_cameras_are_the_models_keyframes(self):
        """~cameras: one frustum a keyframe at sparse/0's camera-to-world pose, in the world
        frame; the refined poses are the node's within the refinement's corrections (2 cm): the
        model's world is the node's."""
        self.assertIsNone(self.model_error)
        msg = self.model_b.cameras
        self.assertEqual(Marker.DELETEALL, msg.markers[0].action)
        frusta = {m.id: m for m in msg.markers[1:]}
        self.assertEqual(len(msg.markers) - 1, len(frusta))
        self.assertEqual(sorted(self.sparse_b.images), sorted(frusta))
        node = {k.image_name: k for k in self.selection.keyframes}
        self.assertEqual(set(node), {self.sparse_b.images[i].name for i in frusta})
        for iid, im in self.sparse_b.images.items():
            m = frusta[iid]
            self.assertEqual(self.selection.header.frame_id, m.header.frame_id)
            self.assertEqual((Marker.LINE_LIST, 16), (m.type, len(m.points)))
            centre, (w, x, y, z) = geometry.camera_to_world(im.qvec, im.tvec)
            p, o = m.pose.position, m.pose.orientation
            np.testing.assert_allclose([p.x, p.y, p.z], centre, atol=1e-9)
            np.testing.assert_allclose([o.w, o.x, o.y, o.z], [w, x, y, z], atol=1e-9)
            k = node[im.name].pose.position
            self.assertLess(np.linalg.norm(np.array([k.x, k.y, k.z]) - centre), 0.02, im.name)

    def test_a_late_subscriber_gets_the_same_model(self):
        self.assertIsNone(self.model_error)
        late = ModelListener(self.bridge_b.name)
        try:
            wait_until(lambda: late.points is not None and late.cameras is not None, 30.0,
                       'the latched ~points and ~cameras')
            self.assertEqual(bytes(self.model_b.points.data), bytes(late.points.data))
            self.assertEqual(self.model_b.points.header.frame_id, late.points.header.frame_id)
            self.assertEqual([(m.id, m.pose) for m in self.model_b.cameras.markers],
                             [(m.id, m.pose) for m in late.cameras.markers])
        finally:
            late.close()

    def test_a_model_nobody_watches_is_not_sent_until_someone_comes(self):
        """Nothing subscribes to bridge_c's ~points and ~cameras during the run: its report counts
        no message sent. One who comes then gets its finished model at once."""
        report = json.load(open(os.path.join(self.c, 'report.json')))
        self.assertEqual(0, report['model_topics']['messages'], report['model_topics'])
        self.assertGreater(report['model_topics']['points'], 100, report['model_topics'])
        model = read_model(os.path.join(self.c, 'sparse', '0'))
        late = ModelListener(self.bridge_c.name)
        try:
            wait_until(lambda: late.points is not None and late.cameras is not None and
                       late.points.width == len(model.points), 30.0,
                       "bridge_c's ~points (sparse/0's %d points) and ~cameras for a subscriber that came "
                       "after the finish" % len(model.points))
            self.assertEqual(sorted(model.images), sorted(m.id for m in late.cameras.markers[1:]))
        finally:
            late.close()

    def test_killed_bridge_ends_like_an_uninterrupted_one(self):
        """The same images extracted (the same keypoints), the same pairs matched and verified.
        COLMAP's CPU SIFT is not bit-reproducible between two runs on the same image (measured:
        one image of 20 with 121 of its 72,960 descriptor bytes different), so descriptors and
        match counts are compared within a small tolerance."""
        a = database_content(os.path.join(self.a, 'database.db'))
        b = database_content(os.path.join(self.b, 'database.db'))
        self.assertGreater(len(a['images']), 0)
        self.assertEqual(a['images'], b['images'])
        self.assertEqual(a['keypoints'], b['keypoints'])
        self.assertEqual(set(a['descriptors']), set(b['descriptors']))
        for name in a['descriptors']:
            da, db = a['descriptors'][name], b['descriptors'][name]
            self.assertEqual(len(da), len(db), name)
            different = sum(1 for x, y in zip(da, db) if x != y)
            self.assertLessEqual(different, 0.01 * len(da), '%s: %d descriptor bytes differ' % (name, different))
        self.assertEqual(set(a['matches']), set(b['matches']))
        for pair, (rows, _) in a['matches'].items():
            self.assertLessEqual(abs(rows - b['matches'][pair][0]), 2 + 0.05 * rows, pair)
        self.assertEqual(set(a['verified']), set(b['verified']))

    def test_nothing_extracted_or_matched_twice(self):
        with open(os.path.join(self.a, 'ledger.txt')) as f:
            lines = [l.split(None, 2)[1:] for l in f if l.strip()]
        extracted = [item for what, item in lines if what == 'extracted']
        matched = [item for what, item in lines if what == 'matched']
        self.assertEqual(len(extracted), len(set(extracted)), 'an image was extracted twice')
        self.assertEqual(len(matched), len(set(matched)), 'a pair was matched twice')
        self.assertGreater(len(matched), self.killed_after, 'the restarted bridge matched nothing')

    def test_consumers_rebuild_the_final_pairs(self):
        self.assertEqual(self.final, self.dropping.current())
        self.assertEqual(self.final, self.late.current())
        self.assertGreater(self.dropping.dropped, 0)
        self.assertGreater(self.dropping.catch_ups, 1, 'the dropping consumer never had to catch up')

    def test_the_node_got_every_frame(self):
        """COLMAP beside it (at a lower priority) takes no frame from the node."""
        self.assertTrue(self.node.alive())
        s = self.statistics.wait(lambda m: m.frames_received >= self.frames, 30.0, 'every frame received')
        self.assertEqual(self.frames, s.images_arrived)
        self.assertEqual(self.frames, s.frames_offered, 'drops: %s %s (%s)' % (s.drop_reasons, s.drop_counts,
                                                                              s.last_error))


if __name__ == '__main__':
    rospy.init_node('live_bridge_tester')
    rostest.rosrun('view_selection', 'live_bridge', LiveBridge, sys.argv)
