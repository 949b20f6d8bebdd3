"""Helpers of the robustness rostests (defects, restart, faults): node processes the tests start,
kill and restart themselves, frames published by the test, statistics watched, service calls and
waits that all have a timeout."""
import io
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time

import numpy
import roslib.packages
import rospy
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image

from view_selection.msg import InputStatistics

PKG = 'view_selection'


def find_tool(name):
    """Path of an executable of this package as rosrun finds it, or None."""
    try:
        found = roslib.packages.find_node(PKG, name)
    except Exception:
        return None
    if isinstance(found, (list, tuple)):
        found = found[0] if found else None
    return found or None


def note_without_real_data(test, folder):
    """`test` runs without the real data in `folder` (synthetic frames instead, or skipped): one
    line to $VIEW_SELECTION_SKIP_LOG, which scripts/test counts (and fails on when the data
    folder exists)."""
    log = os.environ.get('VIEW_SELECTION_SKIP_LOG')
    rospy.logwarn('%s: no real data (%s absent)', test, folder)
    if log:
        with open(log, 'a') as f:
            f.write('%s: no real data (%s absent)\n' % (test, folder))


def node_binary():
    """~node_binary if set (to run a test against another build), else this package's node."""
    return rospy.get_param('~node_binary', '') or find_tool('view_selection_node')


def wait_until(predicate, timeout, what, period=0.02):
    """Polls until predicate() is true; AssertionError naming `what` after `timeout` seconds."""
    deadline = time.time() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.time() > deadline:
            raise AssertionError('%s: not within %.0f s' % (what, timeout))
        time.sleep(period)


# Frames a feeder lets run ahead of what the node's ~statistics show handled (feed). They come
# once per ~publish_period (0.5 s at the defaults), so waiting for each frame alone costs about
# that per frame; with this many in flight, about that per this many. They stay far below every
# queue they pass (the publishers' 50; the node's subscriber_queue_size 100, queue_size 90,
# max_pending_frames 30), so none is lost to a queue, and each topic delivers them in order.
FEED_WINDOW = 8


def feed(publish, frames, handled, timeout, what, window=FEED_WINDOW):
    """Publishes `frames` with publish(frame), never more than `window` ahead of handled() (how
    many of these frames the node has handled so far, from its ~statistics), then waits until
    it has handled them all. Each wait is for a frame handled, within `timeout` seconds."""
    frames = list(frames)
    for n, frame in enumerate(frames, 1):
        if n > window:
            wait_until(lambda: handled() >= n - window, timeout, '%s: frame %d handled' % (what, n - window))
        publish(frame)
    if frames:
        wait_until(lambda: handled() >= len(frames), timeout, '%s: frame %d handled' % (what, len(frames)))


class CallTimeout(AssertionError):
    pass


def call(name, srv_type, request=None, timeout=10.0):
    """Calls a service and returns its response; CallTimeout when it does not answer within
    `timeout` seconds (waiting for the service included)."""
    start = time.time()
    try:
        rospy.wait_for_service(name, timeout=timeout)
    except rospy.ROSException:
        raise CallTimeout('%s is not advertised within %.0f s' % (name, timeout))
    result = {}

    def run():
        try:
            proxy = rospy.ServiceProxy(name, srv_type)
            result['response'] = proxy(request) if request is not None else proxy()
        except Exception as e:  # reported below
            result['error'] = e
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(max(0.1, timeout - (time.time() - start)))
    if thread.is_alive():
        raise CallTimeout('%s did not answer within %.1f s' % (name, timeout))
    if 'error' in result:
        raise result['error']
    return result['response']


class NodeProcess:
    """view_selection_node (or another binary) as a child process of the test, with private
    parameters set on the parameter server first, so a test can SIGKILL and restart it."""

    def __init__(self, name, params, remaps=None, binary=None, args=()):
        self.name = '/' + name.strip('/')
        self.params = params
        self.remaps = remaps or {}
        self.binary = binary or node_binary()
        self.args = list(args)
        self.process = None
        self.log = None

    def start(self):
        assert self.binary, 'view_selection_node is not built'
        if rospy.has_param(self.name):
            rospy.delete_param(self.name)
        for key, value in self.params.items():
            rospy.set_param(self.name + '/' + key, value)
        self.log = tempfile.TemporaryFile(mode='w+')
        cmd = [self.binary] + self.args + ['__name:=' + self.name.lstrip('/')]
        cmd += ['%s:=%s' % (a, b) for a, b in self.remaps.items()]
        self.process = subprocess.Popen(cmd, stdout=self.log, stderr=subprocess.STDOUT)
        return self

    def alive(self):
        return self.process is not None and self.process.poll() is None

    def signal(self, sig):
        if self.alive():
            os.kill(self.process.pid, sig)

    def wait(self, timeout):
        """The exit code; AssertionError when it does not exit within `timeout` seconds."""
        try:
            return self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError('%s did not exit within %.0f s' % (self.name, timeout))

    def stop(self, timeout=20.0):
        """SIGINT (the node saves its session), then SIGKILL if it hangs; returns the exit code."""
        if not self.alive():
            return self.process.returncode if self.process else None
        self.signal(signal.SIGINT)
        try:
            return self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.signal(signal.SIGKILL)
            self.process.wait(timeout=10)
            raise AssertionError('%s ignored SIGINT for %.0f s' % (self.name, timeout))

    def kill(self):
        """SIGKILL: no chance to save or clean up."""
        self.signal(signal.SIGKILL)
        if self.process:
            self.process.wait(timeout=10)

    def output(self):
        if not self.log:
            return ''
        self.log.flush()
        self.log.seek(0)
        return self.log.read()

    def wait_for_services(self, timeout=30.0):
        for srv in ('get_selection', 'reset'):
            try:
                rospy.wait_for_service(self.name + '/' + srv, timeout=timeout)
            except rospy.ROSException:
                raise AssertionError('%s/%s not advertised within %.0f s; output:\n%s'
                                     % (self.name, srv, timeout, self.output()[-3000:]))


class Latest:
    """The latest message of a topic about a node, as `convert(message)` makes it (None: not
    about this node); get() and wait() read it."""

    def __init__(self, node, topic, msg_type, convert=lambda m: m):
        self.node = node.rstrip('/')
        self.lock = threading.Lock()
        self.last = None
        self.convert = convert
        self.subscriber = rospy.Subscriber(topic, msg_type, self._on, queue_size=100)

    def _on(self, msg):
        value = self.convert(msg)
        if value is not None:
            with self.lock:
                self.last = value

    def forget(self):
        """Forgets the last message (before a restart: only the new process's count)."""
        with self.lock:
            self.last = None

    def get(self):
        with self.lock:
            return self.last

    def wait(self, predicate, timeout, what):
        """The first value for which predicate(value) holds."""
        found = []

        def check():
            value = self.get()
            if value is not None and predicate(value):
                found.append(value)
                return True
            return False
        wait_until(check, timeout, '%s %s' % (self.node, what))
        return found[0]

    def close(self):
        self.subscriber.unregister()


class Statistics(Latest):
    """The latest ~statistics of a node (latched, republished on change)."""

    def __init__(self, node):
        Latest.__init__(self, node, node.rstrip('/') + '/statistics', InputStatistics)

    def handled(self):
        """Frames offered or dropped (frame drops only; bad_map counts clouds)."""
        s = self.get()
        if s is None:
            return -1
        drops = sum(c for r, c in zip(s.drop_reasons, s.drop_counts) if r != 'bad_map')
        return s.frames_offered + drops


class Diagnostics(Latest):
    """The latest /diagnostics status of a node, as {key: value} (the updater publishes it once
    a second)."""

    def __init__(self, node):
        from diagnostic_msgs.msg import DiagnosticArray
        prefix = node.strip('/') + ':'

        def values(msg):
            for status in msg.status:
                if status.name.startswith(prefix):
                    return {kv.key: kv.value for kv in status.values}
            return None
        Latest.__init__(self, node, '/diagnostics', DiagnosticArray, values)


# ---------------------------------------------------------------------------------------------
# Frames

class Frame:
    """One frame's messages (image, camera_info, depth, pose) with one stamp."""

    def __init__(self, image, info, depth, pose):
        self.image, self.info, self.depth, self.pose = image, info, depth, pose

    @property
    def stamp(self):
        return self.image.header.stamp


def synthetic_frames(count, width=160, height=120, seed=3, step=0.05):
    """A camera moving sideways in front of a textured wall 2 m away (depth 32FC1, BGR image),
    stamps 100 + 0.1 i; enough for every_frame keyframes that see each other."""
    rng = numpy.random.RandomState(seed)
    texture = rng.randint(0, 255, size=(height, width + count * 8, 3)).astype(numpy.uint8)
    frames = []
    for i in range(count):
        stamp = rospy.Time.from_sec(100.0 + 0.1 * i)
        image = Image(height=height, width=width, encoding='bgr8', is_bigendian=0, step=width * 3)
        image.header.stamp = stamp
        image.header.frame_id = 'camera'
        image.data = texture[:, i * 8:i * 8 + width, :].tobytes()
        depth = Image(height=height, width=width, encoding='32FC1', is_bigendian=0, step=width * 4)
        depth.header = image.header
        depth.data = numpy.full((height, width), 2.0 + 0.01 * i, numpy.float32).tobytes()
        info = CameraInfo(height=height, width=width)
        info.header = image.header
        info.K = [150.0, 0, width / 2.0, 0, 150.0, height / 2.0, 0, 0, 1]
        pose = PoseStamped()
        pose.header.stamp = stamp
        pose.header.frame_id = 'world'
        pose.pose.position.x = step * i
        pose.pose.orientation.w = 1.0
        frames.append(Frame(image, info, depth, pose))
    return frames


def bag_frames(bag_path, limit=None):
    """The frames of a bag written by tum_to_bag (TUM topic names, /camera/pose), in order."""
    import rosbag
    topics = {'/camera/rgb/image_color': 'image', '/camera/rgb/camera_info': 'info',
              '/camera/depth/image': 'depth', '/camera/pose': 'pose'}
    by_stamp = {}
    with rosbag.Bag(bag_path) as bag:
        for topic, msg, _ in bag.read_messages(topics=list(topics)):
            stamp = msg.header.stamp
            by_stamp.setdefault((stamp.secs, stamp.nsecs), {})[topics[topic]] = msg
    frames = []
    for key in sorted(by_stamp):
        parts = by_stamp[key]
        if len(parts) == 4:
            frames.append(Frame(parts['image'], parts['info'], parts['depth'], parts['pose']))
    return frames[:limit] if limit else frames


class FramePublisher:
    """Publishes frames on <prefix>/image, camera_info, depth and pose."""

    def __init__(self, prefix):
        prefix = prefix.rstrip('/')
        self.prefix = prefix
        self.image = rospy.Publisher(prefix + '/image', Image, queue_size=50)
        self.info = rospy.Publisher(prefix + '/camera_info', CameraInfo, queue_size=50)
        self.depth = rospy.Publisher(prefix + '/depth', Image, queue_size=50)
        self.pose = rospy.Publisher(prefix + '/pose', PoseStamped, queue_size=200)

    def remaps(self):
        return {'image': self.prefix + '/image', 'camera_info': self.prefix + '/camera_info',
                'depth': self.prefix + '/depth', 'pose': self.prefix + '/pose'}

    def wait_connected(self, timeout=30.0):
        wait_until(lambda: all(p.get_num_connections() > 0
                               for p in (self.image, self.info, self.depth, self.pose)),
                   timeout, 'subscribers on ' + self.prefix)
        time.sleep(0.3)  # rospy counts a connection before its first message can pass

    def publish(self, frame, pose=True):
        if pose:
            self.pose.publish(frame.pose)
        self.depth.publish(frame.depth)
        self.info.publish(frame.info)
        self.image.publish(frame.image)

    def publish_pose(self, frame):
        self.pose.publish(frame.pose)

    def close(self):
        for p in (self.image, self.info, self.depth, self.pose):
            p.unregister()


def serialized(msg):
    buffer = io.BytesIO()
    msg.serialize(buffer)
    return buffer.getvalue()


def check_selection(test, sel, what):
    """Everything a ViewSelection says must agree with itself: ids, sets, values, pairs, counts."""
    n = len(sel.keyframes)
    test.assertEqual([k.id for k in sel.keyframes], list(range(n)), what + ': keyframe ids')
    test.assertEqual(len(sel.next_view_sets), n, what + ': one next view set per keyframe')
    finals = []
    for i, v in enumerate(sel.next_view_sets):
        test.assertEqual(v.view, i, what)
        final = list(v.next_views) + list(v.completed_views)
        test.assertEqual(len(v.error_resistance), len(v.next_views), what)
        test.assertEqual(len(v.completed_error_resistance), len(v.completed_views), what)
        test.assertLessEqual(len(v.next_views), sel.k, what + ': |C_%d| <= k' % i)
        test.assertEqual(len(set(final)), len(final), what + ': C_%d repeats a view' % i)
        for j in final:
            test.assertTrue(0 <= j < n and j != i, what + ': C_%d names view %d' % (i, j))
        values = list(v.error_resistance)
        test.assertEqual(values, sorted(values), what + ': C_%d not best first' % i)
        finals.append(set(final))
    pairs = [(p.first, p.second) for p in sel.pairs]
    test.assertEqual(pairs, sorted(set(pairs)), what + ': pairs sorted and unique')
    expected_pairs = sorted({(min(i, j), max(i, j)) for i, s in enumerate(finals) for j in s})
    test.assertEqual(pairs, expected_pairs, what + ': pairs are the final sets\' edges')
    entries = sum(len(v.next_views) for v in sel.next_view_sets)
    test.assertGreaterEqual(sel.finite_entries, entries, what + ': finite entries')
    if n == 0 or sel.finite_entries == 0:
        test.assertEqual(sel.start_view, -1, what + ': start view without entries')
    else:
        test.assertTrue(0 <= sel.start_view < n, what + ': start view')
    test.assertEqual(len(set(sel.order)), len(sel.order), what + ': order repeats a view')
    for v in list(sel.order) + list(sel.isolated) + [c.view for c in sel.completed]:
        test.assertTrue(0 <= v < n, what + ': view %d out of range' % v)
    test.assertEqual(list(sel.isolated), sorted(sel.isolated), what + ': isolated ascending')


def frame_drops(s):
    """Frames dropped: not the drops of inputs that never were a received frame (map clouds,
    paths, images lost in roscpp's queues or left without a partner; input_statistics.cpp)."""
    not_frames = ('bad_map', 'bad_path', 'lost_before_node', 'unsynchronised')
    return sum(c for r, c in zip(s.drop_reasons, s.drop_counts) if r not in not_frames)


def check_statistics(test, s, what):
    drops = frame_drops(s)
    test.assertEqual(len(s.drop_reasons), len(s.drop_counts), what)
    test.assertEqual(s.frames_dropped, sum(s.drop_counts), what + ': frames_dropped is the sum')
    test.assertLessEqual(s.keyframes, s.frames_offered, what + ': keyframes <= frames offered')
    test.assertLessEqual(s.frames_offered + drops, s.frames_received,
                         what + ': offered + dropped <= received (%d + %d > %d)'
                         % (s.frames_offered, drops, s.frames_received))


def shut_down(*parts, folder=None):
    """Stops the nodes among `parts` (NodeProcess), closes the rest (subscribers, publishers), and
    removes `folder`."""
    for part in parts:
        if part is not None:
            (part.stop if isinstance(part, NodeProcess) else part.close)()
    if folder:
        shutil.rmtree(folder, ignore_errors=True)
