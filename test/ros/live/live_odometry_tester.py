#!/usr/bin/env python3
"""Issue 29, for real: the built-in sequence as a bag with images and depth only (no /tf, no pose
topic), three frames of it blank and three with depth all zeros, played with rosbag play through
`roslaunch view_selection tum_replay.launch odometry:=true colmap_project:=DIR` at its defaults:
rgbd_odometry (the odometry stand-in) gives the poses, view_selection_node selects, colmap_bridge
matches with COLMAP 3.8 and builds the refined model when the recording ends.

  - the odometry says it lost tracking and counts it (/diagnostics), and keeps tracking after;
  - the model is written, every keyframe in it, and the refined model is closer to the
    sequence's exact poses than the odometry's poses were (sparse/unrefined);
  - report.json gives every keyframe's correction, and ~refined_path carries the refined poses;
  - colmap_from_selection --model known_poses on the node's ~export (the same drifting poses)
    builds the same refined model offline, within a tolerance (see test_offline_gives_the_same).
"""
import json
import math
import os
import shutil
import signal
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
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry, Path
from std_srvs.srv import Trigger

from view_selection.srv import Export, ExportRequest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'robustness'))
from vs_replay import bridge_report_after, final_report, run  # noqa: E402
from vs_robust import NodeProcess, call, find_tool, wait_until  # noqa: E402

from view_selection import geometry  # noqa: E402
from view_selection.colmap.model import read_model  # noqa: E402
from view_selection.evaluation.trajectory import ate_rmse  # noqa: E402

NODE = '/view_selection'
BLANK = (30, 31, 32)      # frames whose image is a uniform grey
NO_DEPTH = (33, 34, 35)   # frames whose depth is all zeros



def exact_poses(folder):
    """{stamp rounded to 1e-6: centre} of the sequence's groundtruth.txt."""
    out = {}
    with open(os.path.join(folder, 'groundtruth.txt')) as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 8 and not parts[0].startswith('#'):
                out[round(float(parts[0]), 6)] = tuple(float(v) for v in parts[1:4])
    return out


def stamp_of(name):
    """The node names keyframe images rgb/<stamp>.png."""
    return round(float(os.path.splitext(os.path.basename(name))[0]), 6)


def centres(model_path):
    m = read_model(model_path)
    return {im.name: geometry.centre_of(im.qvec, im.tvec) for im in m.images.values()}


class LiveOdometry(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.timeout = float(rospy.get_param('~timeout', 180.0))
        cls.frames = int(rospy.get_param('~frames', 90))
        assert shutil.which('colmap'), 'COLMAP is not installed (scripts/install_deps colmap)'
        for tool in ('generate_sequence', 'tum_to_bag', 'colmap_from_selection', 'rgbd_odometry', 'refine_model'):
            assert find_tool(tool), '%s is not built' % tool
        cls.tmp = tempfile.mkdtemp(prefix='view_selection_odometry_')
        cls.source = os.path.join(cls.tmp, 'synthetic')
        run([find_tool('generate_sequence'), '--out', cls.source, '--frames', str(cls.frames), '--width', '320',
             '--height', '240', '--quiet'], 600, 'generate_sequence')
        cls.exact = exact_poses(cls.source)
        # A covered camera and a depth sensor that gives nothing, for three frames each.
        with open(os.path.join(cls.source, 'rgb.txt')) as f:
            rgb = [line.split()[1] for line in f if line.strip() and not line.startswith('#')]
        with open(os.path.join(cls.source, 'depth.txt')) as f:
            depth = [line.split()[1] for line in f if line.strip() and not line.startswith('#')]
        for q in BLANK:
            image = cv2.imread(os.path.join(cls.source, rgb[q]))
            cv2.imwrite(os.path.join(cls.source, rgb[q]), np.full_like(image, 120))
        for q in NO_DEPTH:
            d = cv2.imread(os.path.join(cls.source, depth[q]), cv2.IMREAD_ANYDEPTH)
            cv2.imwrite(os.path.join(cls.source, depth[q]), np.zeros_like(d))
        cls.bag = os.path.join(cls.tmp, 'no_poses.bag')
        run([find_tool('tum_to_bag'), '--dataset', cls.source, '--out', cls.bag, '--no-poses', '--quiet'], 600,
            'tum_to_bag')
        cls.bag_topics = run(['rosbag', 'info', cls.bag], 120, 'rosbag info')

        cls.project = os.path.join(cls.tmp, 'project')
        cls.launch_log = open(os.path.join(cls.tmp, 'launch.log'), 'w+')
        cls.launch = subprocess.Popen(
            ['roslaunch', 'view_selection', 'tum_replay.launch', 'play:=false', 'bag:=none', 'odometry:=true',
             'colmap_project:=' + cls.project, 'output:=screen'],
            stdout=cls.launch_log, stderr=subprocess.STDOUT, start_new_session=True)
        cls.lock = threading.Lock()
        cls.diagnostics, cls.path, cls.odometry_stamps = None, None, []
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.on_diagnostics, queue_size=10)
        rospy.Subscriber('/colmap_bridge/refined_path', Path, cls.on_path, queue_size=2)
        rospy.Subscriber('/view_selection_odometry/odometry', Odometry, cls.on_odometry, queue_size=1000)
        try:
            for service in (NODE + '/get_pairs', '/colmap_bridge/finish'):
                rospy.wait_for_service(service, timeout=cls.timeout)
            wait_until(lambda: cls.subscribed(), cls.timeout, 'rgbd_odometry subscribed', period=0.5)
        except (rospy.ROSException, AssertionError) as e:
            raise AssertionError('%s; roslaunch said:\n%s' % (e, cls.output()[-3000:]))
        run(['rosbag', 'play', '--clock', '-q', '-d', '1', cls.bag], 60 + 10 * cls.frames / 30.0, 'rosbag play')
        cls.bag_end = time.time()
        try:
            cls.report, cls.selection = wait_until(final_report(cls.project, cls.bag_end, NODE), 3 * cls.timeout,
                                                   'the bridge wrote the model of the final selection', period=0.5)
        except AssertionError as e:
            raise AssertionError('%s; roslaunch said:\n%s' % (e, cls.output()[-4000:]))
        # The path of this model (the bridge publishes it after writing report.json; a finish
        # during a pause of the recording may have published an earlier one).
        last_stamp = max(k.stamp.to_sec() for k in cls.selection.keyframes)

        def final_path():
            with cls.lock:
                p = cls.path
            return p is not None and len(p.poses) == cls.report['registered'] and \
                abs(p.poses[-1].header.stamp.to_sec() - last_stamp) < 1e-6
        wait_until(final_path, 30.0, 'the refined path of the final model is published', period=0.2)
        wait_until(lambda: int((cls.odometry_status() or {}).get('images', 0)) >= cls.frames, 30.0,
                   "the odometry's diagnostics count every image", period=0.2)
        # Offline from the node's export: the same keyframes at the same (odometry) poses.
        cls.export = os.path.join(cls.tmp, 'export')
        answer = call(NODE + '/export', Export, ExportRequest(directory=cls.export), 60.0)
        assert answer.success, answer.message
        cls.offline = os.path.join(cls.tmp, 'offline')
        run([find_tool('colmap_from_selection'), cls.export, '--model', 'known_poses', '--image-path',
             os.path.join(cls.project, 'images'), '--out', cls.offline], 900, 'colmap_from_selection')

    @classmethod
    def subscribed(cls):
        out = subprocess.run(['rosnode', 'info', '-q', '/view_selection_odometry'], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, universal_newlines=True, timeout=30).stdout
        return '/camera/depth/image' in out.split('Subscriptions:')[-1]

    @classmethod
    def on_diagnostics(cls, msg):
        for status in msg.status:
            if 'rgbd_odometry' in status.name or status.hardware_id == 'rgbd_odometry':
                with cls.lock:
                    cls.diagnostics = {kv.key: kv.value for kv in status.values}
                    cls.diagnostics['message'] = status.message

    @classmethod
    def on_path(cls, msg):
        with cls.lock:
            cls.path = msg

    @classmethod
    def on_odometry(cls, msg):
        with cls.lock:
            cls.odometry_stamps.append(msg.header.stamp.to_sec())

    @classmethod
    def odometry_status(cls):
        with cls.lock:
            return dict(cls.diagnostics) if cls.diagnostics else None

    @classmethod
    def output(cls):
        cls.launch_log.flush()
        cls.launch_log.seek(0)
        return cls.launch_log.read()

    @classmethod
    def tearDownClass(cls):
        launch = getattr(cls, 'launch', None)
        if launch and launch.poll() is None:
            os.killpg(launch.pid, signal.SIGINT)
            try:
                launch.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(launch.pid, signal.SIGKILL)
                launch.wait(10)
        if os.environ.get('VIEW_SELECTION_KEEP_TEST_OUTPUT'):
            rospy.loginfo('odometry test output kept in %s', cls.tmp)
        else:
            shutil.rmtree(cls.tmp, ignore_errors=True)

    # -- the tests ----------------------------------------------------------------------------
    def test_the_bag_has_no_poses(self):
        self.assertIn('/camera/rgb/image_color', self.bag_topics)
        self.assertIn('/camera/depth/image', self.bag_topics)
        for topic in ('/tf', '/camera/pose'):
            self.assertNotIn(topic + ' ', self.bag_topics)

    def test_lost_tracking_is_said_and_counted(self):
        status = self.odometry_status()
        self.assertGreaterEqual(int(status['lost']), 3, status)  # frames may be skipped when it is busy
        self.assertLessEqual(int(status['lost']), len(BLANK) + len(NO_DEPTH), status)
        self.assertGreaterEqual(int(status['tracked']), self.frames - len(BLANK) - len(NO_DEPTH) - 5, status)
        self.assertEqual('0', status['restarts'], status)
        self.assertIn('no usable depth', status['last lost'])  # the depth frames come last
        out = self.output()
        self.assertIn('rgbd_odometry: tracking lost at', out)
        # No pose for a frame it lost; poses again after them.
        bad = {round(1000.0 + q / 30.0, 3) for q in BLANK + NO_DEPTH}
        with self.lock:
            stamps = {round(s, 3) for s in self.odometry_stamps}
        self.assertFalse(bad & stamps, 'odometry published for frames it could not track')
        self.assertTrue(any(s > max(bad) for s in stamps), 'tracking did not resume')

    def test_every_keyframe_is_in_the_refined_model(self):
        names = {k.image_name for k in self.selection.keyframes}
        self.assertGreaterEqual(len(names), 5)
        for folder in ('0', 'unrefined'):
            self.assertEqual(names, set(centres(os.path.join(self.project, 'sparse', folder))), folder)
        r = self.report
        self.assertTrue(r['refinement']['refined'], r['refinement'])
        self.assertEqual(len(names), r['registered'])
        self.assertEqual(names, {k['name'] for k in r['refinement']['keyframes']})
        for k in r['refinement']['keyframes']:
            self.assertTrue(math.isfinite(k['translation']) and math.isfinite(k['rotation_deg']), k)
        self.assertGreater(r['points'], 100)

    def test_the_refined_model_is_closer_than_the_odometry(self):
        def ate(folder):
            c = centres(os.path.join(self.project, 'sparse', folder))
            names = sorted(n for n in c if stamp_of(n) in self.exact)
            return ate_rmse([c[n] for n in names], [self.exact[stamp_of(n)] for n in names])
        odometry, refined = ate('unrefined'), ate('0')
        rospy.loginfo('keyframes: odometry ATE %.4f m, refined %.4f m', odometry, refined)
        self.assertGreater(odometry, 0.0)
        self.assertLess(refined, odometry, 'the refined model (%.4f m) is not closer than the odometry (%.4f m)'
                        % (refined, odometry))

    def test_the_refined_path_is_published(self):
        model = read_model(os.path.join(self.project, 'sparse', '0')).image_by_name()
        by_stamp = {round(k.stamp.to_sec(), 6): k.image_name for k in self.selection.keyframes}
        self.assertEqual('odom', self.path.header.frame_id)
        self.assertEqual(len(model), len(self.path.poses))
        for p in self.path.poses:
            name = by_stamp[round(p.header.stamp.to_sec(), 6)]
            centre, q = geometry.camera_to_world(model[name].qvec, model[name].tvec)
            self.assertAlmostEqual(0.0, math.dist(centre, (p.pose.position.x, p.pose.position.y, p.pose.position.z)),
                                   delta=1e-9)
            o = p.pose.orientation
            dot = abs(sum(a * b for a, b in zip(q, (o.w, o.x, o.y, o.z))))  # the same rotation: |q . q'| = 1
            self.assertGreater(dot, 1.0 - 1e-12, (q, o))

    def test_offline_gives_the_same_refined_model(self):
        """colmap_from_selection on the export (the odometry's poses) refines the whole model to
        convergence; the bridge refined as the recording went on (refinement/local.py: windows,
        the whole model when its budget allowed, the finish what changed since), along another
        path. So the same keyframes must be in both, at the same unrefined poses, and the online
        model as close to the exact poses as the offline one: its ATE at most 1.1x the offline's
        (issue 34's goal) plus 2 mm (the databases differ: the bridge also matched pairs announced
        and later taken back, and COLMAP's RANSAC for the pairs that fell back to it)."""
        online = centres(os.path.join(self.project, 'sparse', '0'))
        offline = centres(os.path.join(self.offline, 'sparse', '0'))
        self.assertEqual(sorted(online), sorted(offline))
        on_u = centres(os.path.join(self.project, 'sparse', 'unrefined'))
        off_u = centres(os.path.join(self.offline, 'sparse', 'unrefined'))
        for name in on_u:
            self.assertLess(math.dist(on_u[name], off_u[name]), 1e-6, name)
        with open(os.path.join(self.offline, 'report.json')) as f:
            off_report = json.load(f)
        self.assertTrue(off_report['refinement']['refined'], off_report['refinement'])
        self.assertNotEqual('out_of_time', off_report['refinement']['status'])  # offline: no budget
        def ate(c):
            names = sorted(n for n in c if stamp_of(n) in self.exact)
            return ate_rmse([c[n] for n in names], [self.exact[stamp_of(n)] for n in names])
        on, off, odometry = ate(online), ate(offline), ate(on_u)
        rospy.loginfo('refined ATE online %.5f m, offline %.5f m, odometry %.5f m (%s)', on, off, odometry,
                      self.report['refinement'].get('live'))
        if self.report['refinement']['status'] == 'out_of_time':
            # The finish's refinement stops at ~refine_max_seconds (5 s; about 2 s of CPU here):
            # on a machine too loaded to give it that, it ends where it got to, and the offline
            # one, without a budget, goes further; how far depends on the load, so the 1.1x is
            # measured in a benchmark (dev/benchmark_drift live), not asserted here. What holds
            # at any load: the report names the budget, and what was reached is a correction.
            self.assertIn('time budget', self.report['refinement']['message'])
            self.assertLess(on, odometry, 'online refined ATE %.5f m, odometry %.5f m' % (on, odometry))
            return
        self.assertLess(on, 1.1 * off + 0.002, 'online refined ATE %.5f m, offline %.5f m' % (on, off))

    def test_a_finish_cut_short_is_refined_afterwards(self):
        """Issue 34: a long session's finish cannot refine within ~refine_max_seconds (30
        minutes: nothing begun); the bridge then goes on refining in the background
        (~refine_afterwards, on) and replaces sparse/0 when that converged. This session is
        short, so a second colmap_bridge on the same node, with a budget of 0.2 s where the
        default 5 s refines it within the finish, stands for a long one; the rest is at its
        defaults. Its finish is cut short; afterwards sparse/0 holds every keyframe, refined as
        close to the exact poses as the offline refinement to convergence (issue 34's goal: at
        most 1.1x plus 2 mm, as test_offline_gives_the_same_refined_model), report.json says so,
        and ~refined_path carries the new poses."""
        project = os.path.join(self.tmp, 'project_afterwards')
        os.makedirs(project)
        os.symlink(os.path.join(self.project, 'images'), os.path.join(project, 'images'))  # the node's one folder
        bridge = NodeProcess('/colmap_bridge_afterwards', {'project': project, 'node': NODE, 'refine_max_seconds': 0.2},
                             binary=find_tool('colmap_bridge'))
        paths = []
        sub = rospy.Subscriber(bridge.name + '/refined_path', Path, paths.append, queue_size=5)
        bridge.start()
        try:
            answer = call(bridge.name + '/finish', Trigger, None, 3 * self.timeout)
            self.assertTrue(answer.success, answer.message)
            report = wait_until(bridge_report_after(project, 0.0), 3 * self.timeout,
                                'the refinement after the finish ended', period=0.2)
            # The path of the model refined afterwards (published after report.json; the finish's
            # own may come before it).
            model = read_model(os.path.join(project, 'sparse', '0')).image_by_name()
            by_stamp = {round(k.stamp.to_sec(), 6): k.image_name for k in self.selection.keyframes}

            def path_of_the_model():
                if not paths or len(paths[-1].poses) != len(model):
                    return False
                for p in paths[-1].poses:
                    im = model[by_stamp[round(p.header.stamp.to_sec(), 6)]]
                    centre, _ = geometry.camera_to_world(im.qvec, im.tvec)
                    if math.dist(centre, (p.pose.position.x, p.pose.position.y, p.pose.position.z)) > 1e-9:
                        return False
                return True
            wait_until(path_of_the_model, 30.0, "~refined_path of the model refined after the finish", period=0.2)
            said = bridge.output()
        except AssertionError as e:
            raise AssertionError('%s; the bridge said:\n%s' % (e, bridge.output()[-4000:]))
        finally:
            sub.unregister()
            bridge.stop(60.0)
        self.assertEqual('out_of_time', report['refinement']['status'], report['refinement'].get('message'))
        # One finish: the one asked for. Nothing changed since (the recording had ended), so no
        # idle finish repeats it (the bridge caught up with the node within that finish).
        self.assertEqual(1, said.count('colmap_bridge: finishing ('), said[-4000:])
        after = report['refinement_afterwards']
        self.assertEqual('converged', after['status'], after)
        self.assertTrue(after['refined'])
        self.assertEqual(0.0, after['options']['max_seconds'])  # no budget
        self.assertGreater(after['matches'], 0)
        names = {k.image_name for k in self.selection.keyframes}
        online = centres(os.path.join(project, 'sparse', '0'))
        self.assertEqual(names, set(online))
        self.assertEqual(len(names), report['registered'])
        self.assertEqual(after['statistics']['points'], report['points'])
        self.assertEqual(len(read_model(os.path.join(project, 'sparse', '0')).points), report['points'])

        def ate(c):
            named = sorted(n for n in c if stamp_of(n) in self.exact)
            return ate_rmse([c[n] for n in named], [self.exact[stamp_of(n)] for n in named])
        on, off = ate(online), ate(centres(os.path.join(self.offline, 'sparse', '0')))
        odometry = ate(centres(os.path.join(project, 'sparse', 'unrefined')))
        rospy.loginfo('refined after the finish: ATE %.5f m (offline %.5f m, odometry %.5f m) in %.1f s',
                      on, off, odometry, after['seconds'])
        self.assertLess(on, 1.1 * off + 0.002, 'refined afterwards %.5f m, offline %.5f m' % (on, off))
        self.assertLess(on, odometry)


if __name__ == '__main__':
    rospy.init_node('live_odometry_tester')
    rostest.rosrun('view_selection', 'live_odometry', LiveOdometry, sys.argv)
