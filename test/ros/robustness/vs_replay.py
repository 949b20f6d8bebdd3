"""Bag replays for the rostests: run a tool, play a bag into nodes once they listen, wait for the
subscriptions, wait until the nodes have handled what arrived, stamps in nanoseconds. Shared by
the replay, TUM-layout, compressed, corrections, SLAM, time-jump, restart and live testers."""
import json
import os
import shutil
import signal
import subprocess
import time

import rosgraph
import rospy
from std_srvs.srv import SetBool, SetBoolRequest
from view_selection.srv import GetSelection
from xmlrpc.client import ServerProxy

from vs_robust import call


def run(cmd, timeout, what, env=None):
    """Runs a command; fails with its output when it does not exit 0 within timeout seconds."""
    try:
        done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout,
                              universal_newlines=True, env=env)
    except subprocess.TimeoutExpired as e:
        raise AssertionError('%s did not finish within %.0f s: %s\n%s' % (what, timeout, ' '.join(cmd),
                                                                          e.output or ''))
    if done.returncode != 0:
        raise AssertionError('%s failed (exit %d): %s\n%s' % (what, done.returncode, ' '.join(cmd), done.stdout))
    return done.stdout


def stamp_ns(seconds):
    return int(round(seconds * 1e9))


def msg_stamp_ns(t):
    return t.secs * 1000000000 + t.nsecs


def play_bag(bag, rate, wanted, frames, timeout, play_timeout, start=0.0, counted=None):
    """Plays `bag` at `rate` (from `start` s into it) into the nodes of `wanted` (node -> topics)
    and returns once each node of `counted` (default: all of `wanted`) counted `frames` images
    and depth images (~statistics), or after `play_timeout` s.

    The player starts paused and is unpaused when its own bus information lists each node on each
    of its topics (a fixed delay lost the first frame on a loaded machine). It is kept alive
    (--keep-alive) until the nodes have everything: a player that exits right after its last
    message can take the last image, still queued for a lagging connection, with it (stop 26: 119
    of 120 images at four nodes)."""
    from view_selection.msg import InputStatistics
    player_name = '/replay_player'
    play = ['rosbag', 'play', '--clock', '-q', '--pause', '--keep-alive', '-r', str(rate), '-s', repr(start),
            bag, '__name:=' + player_name.lstrip('/')]
    player = subprocess.Popen(play, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              universal_newlines=True)
    try:
        master = rosgraph.Master(rospy.get_name())
        want = {(node, topic) for node, topics in wanted.items() for topic in topics}
        deadline = time.time() + timeout
        missing = want
        while time.time() < deadline and missing:
            try:
                api = master.lookupNode(player_name)
                info = ServerProxy(api).getBusInfo(rospy.get_name())[2]
                # [id, destination (the subscriber's name), direction, transport, topic, ...]
                have = {(c[1], c[4]) for c in info if c[2] == 'o' and (len(c) < 6 or c[5])}
                missing = {w for w in want if w not in have}
            except Exception:  # the player is not registered yet
                pass
            if missing:
                time.sleep(0.1)
        if missing:
            raise AssertionError('the player did not connect to %s within %.0f s' % (sorted(missing), timeout))
        # Counts are per session: a play after a time jump counts from zero, another play adds.
        counted = list(wanted if counted is None else counted)
        base = {node: rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=timeout)
                for node in counted}

        def arrived(node, s):
            b = base[node] if s.time_jumps == base[node].time_jumps else None
            counts = [s.images_arrived - (b.images_arrived if b else 0)]
            if rospy.get_param(node + '/use_depth', True):
                counts.append(s.depths_arrived - (b.depths_arrived if b else 0))
            return min(counts)
        call(player_name + '/pause_playback', SetBool, SetBoolRequest(data=False), timeout)
        deadline = time.time() + play_timeout
        pending = set(counted)
        while pending and time.time() < deadline:
            if player.poll() is not None:
                raise AssertionError('rosbag play failed (exit %d): %s' % (player.returncode, player.stdout.read()))
            for node in sorted(pending):
                try:
                    s = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=5.0)
                except rospy.ROSException:
                    continue
                if arrived(node, s) >= frames:
                    pending.discard(node)
            time.sleep(0.2)
        # Nodes still short of frames: the tests' counts say which and how many.
    finally:
        if player.poll() is None:
            player.send_signal(signal.SIGINT)
            try:
                player.wait(10)
            except subprocess.TimeoutExpired:
                player.kill()
                player.wait(10)


def wait_for_subscribers(wanted, timeout):
    """Waits (at most `timeout` s) until each node of `wanted` (node -> topics) subscribes to each
    of its topics; raises AssertionError naming what is missing."""
    master = rosgraph.Master(rospy.get_name())
    deadline = time.time() + timeout
    missing = []
    while time.time() < deadline:
        subscribers = {topic: set(names) for topic, names in master.getSystemState()[1]}
        missing = ['%s on %s' % (node, topic) for node, topics in wanted.items() for topic in topics
                   if node not in subscribers.get(topic, ())]
        if not missing:
            return
        time.sleep(0.2)
    raise AssertionError('not subscribed within %.0f s: %s' % (timeout, ', '.join(missing)))


def wait_until_processed(nodes, timeout):
    """Until every node of `nodes` has handled every image that arrived (the last one waits for
    the synchroniser's timeout) and its counts stopped changing for a second."""
    from view_selection.msg import InputStatistics
    deadline = time.time() + timeout
    for node in nodes:
        last, since = None, time.time()
        while time.time() < deadline:
            s = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=timeout)
            key = (s.images_arrived, s.frames_received, s.frames_offered, s.frames_dropped, s.images_in_synchroniser)
            done = s.images_in_synchroniser == 0 and s.frames_offered + s.frames_dropped >= s.images_arrived
            if key != last:
                last, since = key, time.time()
            elif done and time.time() - since > 1.0:
                break
            time.sleep(0.2)


def wait_for_services(nodes, timeout, service='get_selection'):
    """Waits until each node advertises `service`; AssertionError naming the first that does not."""
    for node in nodes:
        try:
            rospy.wait_for_service(node + '/' + service, timeout=timeout)
        except rospy.ROSException:
            raise AssertionError('%s/%s was not advertised within %.0f s' % (node, service, timeout))


def remove_output(folder, what):
    """Removes a test's folder, or keeps it (and says where) with VIEW_SELECTION_KEEP_TEST_OUTPUT."""
    if os.environ.get('VIEW_SELECTION_KEEP_TEST_OUTPUT'):
        rospy.loginfo('%s output kept in %s', what, folder)
    else:
        shutil.rmtree(folder, ignore_errors=True)


def bag_test_setup(cls, name, max_frames, skip_note=None):
    """The parameters of a bag-replay tester (~nodes, ~rate, ~max_frames, ~timeout, ~dataset) as
    attributes of `cls`, its own temporary folder, and tum_to_bag and select_views. Without the
    TUM folder, `cls.skip_reason` says so (and note_without_real_data records it under
    `skip_note`) and None is returned."""
    import tempfile
    from vs_robust import find_tool, note_without_real_data
    cls.nodes = rospy.get_param('~nodes').split()
    cls.rate = float(rospy.get_param('~rate', 1.0))
    cls.max_frames = int(rospy.get_param('~max_frames', max_frames))
    cls.timeout = float(rospy.get_param('~timeout', 60.0))
    cls.dataset = rospy.get_param('~dataset', '')
    cls.tmp = tempfile.mkdtemp(prefix='view_selection_%s_' % name)
    cls.skip_reason = None
    if not os.path.isfile(os.path.join(cls.dataset, 'groundtruth.txt')):
        if skip_note:
            note_without_real_data(skip_note, cls.dataset)
        cls.skip_reason = 'no TUM folder at %s (the kitchen in ../shared/data)' % cls.dataset
        return None
    tools = find_tool('tum_to_bag'), find_tool('select_views')
    if not all(tools):
        raise AssertionError('tum_to_bag or select_views is not built (build the package first)')
    return tools


def tum_rows(folder, name):
    """The rows of a TUM list (rgb.txt, depth.txt, groundtruth.txt) of `folder`, split, without
    comments and empty lines."""
    with open(os.path.join(folder, name)) as f:
        return [line.split() for line in f if line.strip() and not line.startswith('#')]


def skip_without_data(test, what):
    """setUp of a bag-replay tester: skips (saying why) when setUpClass found no data."""
    if test.skip_reason:
        rospy.logwarn('%s skipped: %s', what, test.skip_reason)
        test.skipTest(test.skip_reason)


def assert_every_frame_offered(test, node, frames, timeout):
    """Every one of `frames` colour and depth images arrived at `node` and became a frame offered
    to the keyframe policy, none dropped; returns the node's ~statistics."""
    from view_selection.msg import InputStatistics
    stats = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=timeout)
    reasons = dict(zip(stats.drop_reasons, stats.drop_counts))
    test.assertEqual(stats.frames_dropped, 0, '%s dropped frames: %s (last: %s)' % (node, reasons, stats.last_error))
    test.assertEqual(stats.images_arrived, frames, node + ': images arrived')
    test.assertEqual(stats.depths_arrived, frames, node + ': depth images arrived')
    test.assertEqual(stats.frames_received, frames, node + ': frames synchronised')
    test.assertEqual(stats.frames_offered, frames, node + ': frames offered to the policy')
    return stats


def wait_for_statistics(node, predicate, timeout, what):
    """The first ~statistics of `node` (each read as it comes) for which predicate holds;
    AssertionError naming `what` and the last statistics after `timeout` s."""
    from view_selection.msg import InputStatistics
    deadline, s = time.time() + timeout, None
    while time.time() < deadline:
        s = rospy.wait_for_message(node + '/statistics', InputStatistics, timeout=timeout)
        if predicate(s):
            return s
        time.sleep(0.2)
    raise AssertionError('%s: not within %.0f s (last statistics: %s)' % (what, timeout, s))


def bridge_report_after(project, since):
    """A predicate for wait_until: colmap_bridge's report.json in `project` once it was written
    after `since` (time.time()), else None (missing, half written or older). A finish whose
    refinement its budget cut short is followed by a refinement in the background that replaces
    sparse/0 (refinement_afterwards "running" meanwhile): the report once that ended, so that
    sparse/0 and the report stay as the test reads them."""
    path = os.path.join(project, 'report.json')

    def report():
        try:
            with open(path) as f:
                r = json.load(f)
        except (OSError, ValueError):
            return None
        if (r.get('refinement_afterwards') or {}).get('status') == 'running':
            return None
        return r if r.get('finished_at', 0) > since else None
    return report


def final_report(project, since, node):
    """A predicate for wait_until: (report.json, the node's selection) once colmap_bridge wrote a
    report after `since` (as bridge_report_after) of as many keyframes as the node's selection
    holds, else None. The bridge finishes after ~finish_after_idle without a keyframe, which a
    loaded machine can give before the recording's last keyframe (the odometry or the node
    behind): that finish's report comes after the bag's end too, and a later finish replaces it;
    the report of the final selection is the one a test compares with the selection."""
    report = bridge_report_after(project, since)

    def final():
        r = report()
        if r is None:
            return None
        selection = call(node + '/get_selection', GetSelection, None, 30.0).selection
        return (r, selection) if r.get('keyframes') == len(selection.keyframes) else None
    return final
