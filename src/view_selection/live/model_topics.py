"""colmap_bridge's model on ROS topics (issue 36), for RViz beside the node's markers:

  ~points   sensor_msgs/PointCloud2 (x, y, z float32, rgb), latched: the model's points, coloured
            from the keyframe images, in the node's world frame;
  ~cameras  visualization_msgs/MarkerArray, latched: one frustum (LINE_LIST, green) a keyframe of
            the model at its pose (marker id: the COLMAP image id, ns "cameras").

What is shown comes from live/visualisation.py: the live model as it grows, the finished
(refined) model after a finish. The live model's updates are taken in the bridge's worker (under
its `work` lock, so the live model does not change meanwhile); the finished model is read by the
sending thread once the finish wrote its report. Both are sent by that thread at most once per
`period` (the newest state; a subscriber that joins late gets it latched), and no more often than
keeps that thread within MAX_SEND_CPU of a core: a message's cost grows with the model (a
30-minute walk's 5,636 frusta and 215,000 points sent twice a second took 479 s of CPU, a third
of the bridge's).
"""
import threading
import time

import rospy
from geometry_msgs.msg import Point
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import Marker, MarkerArray

from ..colmap import model as colmap_model
from .visualisation import FIELDS, POINT_STEP, ModelView

# [cores] The share of a core the sending thread may take on average: after a round that took c
# seconds of its CPU the next waits at least c / MAX_SEND_CPU.
MAX_SEND_CPU = 0.05


class ModelTopics:
    def __init__(self, image_dir, frame, period=0.5, frustum_depth=0.1, log=None):
        """frame: a function giving the node's world frame ("" while it is not known)."""
        self.view = ModelView(image_dir, frustum_depth)
        self.frame, self.period = frame, max(0.0, float(period))
        self.log = log or (lambda level, text: None)
        self.lock = threading.Condition()
        # Sent only while someone subscribes (a message of a 30-minute session's model took 20 s of
        # CPU over the session for nobody); one who comes gets the newest state at once.
        listener = _Arrivals(self.lock)
        self.points = rospy.Publisher("~points", PointCloud2, queue_size=1, latch=True, subscriber_listener=listener)
        self.cameras = rospy.Publisher("~cameras", MarkerArray, queue_size=1, latch=True,
                                       subscriber_listener=listener)
        self.sent = (0, 0)         # the view's (cloud, cameras) versions last published
        self.stopping = False
        self.published = 0         # rounds sent: ~points, and ~cameras when they changed
        self.update_cpu = 0.0      # [s] CPU of the updates (the bridge's worker, under `lock`)
        self.send_cpu = 0.0        # [s] CPU of the sending thread: copies, messages, serialisation
        self.markers = {}          # image id -> (its Frustum, its Marker): made once a pose
        self.pending = None        # (sparse/0, the view's cloud_version at the finish) to show
        self.thread = threading.Thread(target=self.loop, name="model_topics", daemon=True)
        self.thread.start()

    # -- from the bridge's worker ------------------------------------------------------------------
    def live(self, model):
        """After an update of the live model (live/model.py; None: no live model). Returns the
        view's version after it (for finished())."""
        with self.lock:
            if model is None:
                return self.view.cloud_version
            start = time.thread_time()
            self.view.live(model)
            self.update_cpu += time.thread_time() - start
            if self.sent != (self.view.cloud_version, self.view.cameras_version):
                self.lock.notify_all()
            return self.view.cloud_version

    def finished(self, report, version):
        """After a finish, its report written: the model it wrote (report["model_path"]: sparse/0,
        refined when the refinement ran) is shown, read by the sending thread, not by the finish:
        reading and colouring a 30-minute session's model (5,597 keyframes, 212,000 points) took
        4.2 s, which the finish spent before its report. Shown only while the live model has not
        changed since (the recording went on: the live model is newer). The mapper's model is in a
        frame of its own, not the node's world: the live model stays shown then. version: what
        live() returned for the live model the finish took."""
        if report.get("model") == "mapper" or not report.get("model_path"):
            return
        with self.lock:
            self.pending = (report["model_path"], version)
            self.lock.notify_all()

    def _show_finished(self, path, version):
        """In the sending thread: the finished model read, then shown unless the live model
        changed since the finish (its view's cloud_version then moved on)."""
        start = time.thread_time()
        try:
            model = colmap_model.read_model(path)
        except colmap_model.ModelError as e:
            self.log("error", "the finished model is not shown: %s" % e)
            return
        with self.lock:
            if self.view.finished(model, version):
                self.lock.notify_all()
            self.update_cpu += time.thread_time() - start

    def stop(self):
        with self.lock:
            self.stopping = True
            self.lock.notify_all()

    # -- the sending thread ------------------------------------------------------------------------
    def loop(self):
        last, pause = 0.0, self.period
        while not rospy.is_shutdown():
            with self.lock:
                while not self.stopping and self.pending is None and (not any(self._due()) or not self.frame()):
                    self.lock.wait(1.0)
                    if rospy.is_shutdown():
                        return
                if self.stopping:
                    return
                pending, self.pending = self.pending, None
            if pending is not None:
                self._show_finished(*pending)
                continue  # then sent as any change, after the pause
            wait = last + pause - time.monotonic()
            if wait > 0:
                time.sleep(wait)  # at most once a period: what changed meanwhile goes out together
            last = time.monotonic()
            try:
                cost = self.publish()
            except rospy.ROSException:
                return  # shutting down
            pause = max(self.period, cost / MAX_SEND_CPU)

    def figures(self):
        """What publishing cost, for report.json: messages sent, CPU seconds of the updates and of
        the sending (this process's threads only; the thread's own clock, so a loaded machine
        does not inflate it), the points shown."""
        with self.lock:
            return {"messages": self.published, "update_cpu_seconds": round(self.update_cpu, 4),
                    "send_cpu_seconds": round(self.send_cpu, 4), "points": len(self.view.cloud()),
                    "cameras": len(self.view.frusta()), "images_decoded": self.view.colours.decoded}

    def _due(self):
        """(~points, ~cameras): whether each has a subscriber and a state it was not sent. Under
        `lock`."""
        return (self.view.cloud_version != self.sent[0] and self.points.get_num_connections() > 0,
                self.view.cameras_version != self.sent[1] and self.cameras.get_num_connections() > 0)

    def publish(self):
        """One round: what changed since the last, sent to the topics someone subscribes to;
        returns its CPU [s]."""
        start = time.thread_time()
        frame = self.frame()
        with self.lock:  # a consistent snapshot: the buffer's bytes and the frusta as they are now
            versions = (self.view.cloud_version, self.view.cameras_version)
            points_due, cameras_due = self._due()
            if points_due:
                cloud = self.view.cloud()
                payload, count = cloud.payload(), len(cloud)
            frusta = list(self.view.frusta()) if cameras_due else None
        stamp = rospy.Time.now()
        if points_due:
            self.points.publish(cloud_message(payload, count, frame, stamp))
        if frusta is not None:
            self.cameras.publish(camera_markers(frusta, frame, stamp, self.view.frustum_depth, self.markers))
        with self.lock:
            self.sent = (versions[0] if points_due else self.sent[0], versions[1] if cameras_due else self.sent[1])
            self.published += 1
            cost = time.thread_time() - start
            self.send_cpu += cost
        return cost


class _Arrivals(rospy.SubscribeListener):
    """Wakes the sending thread when a subscriber comes: what it has not been sent goes out."""

    def __init__(self, condition):
        super().__init__()
        self.condition = condition

    def peer_subscribe(self, topic_name, topic_publish, peer_publish):
        with self.condition:
            self.condition.notify_all()


def cloud_message(payload, count, frame, stamp):
    msg = PointCloud2()
    msg.header.frame_id, msg.header.stamp = frame, stamp
    msg.height, msg.width = 1, count
    msg.fields = [PointField(name=name, offset=offset, datatype=PointField.FLOAT32, count=1) for name, offset in FIELDS]
    msg.is_bigendian = False
    msg.point_step, msg.row_step = POINT_STEP, POINT_STEP * count
    msg.data = payload
    msg.is_dense = True
    return msg


def camera_markers(frusta, frame, stamp, depth, cache=None):
    """DELETEALL, then one LINE_LIST a keyframe: its pose is the camera's in the world frame, its
    points the frustum in the camera frame. cache: {image id: (Frustum, Marker)}, the markers of
    frusta sent before, taken again while their frustum is the same object (and updated)."""
    out = MarkerArray()
    clear = Marker()
    clear.header.frame_id, clear.header.stamp = frame, stamp
    clear.ns, clear.action = "cameras", Marker.DELETEALL
    out.markers.append(clear)
    for f in frusta:
        known = cache.get(f.id) if cache is not None else None
        if known is not None and known[0] is f:
            m = known[1]
            m.header.frame_id, m.header.stamp = frame, stamp
            out.markers.append(m)
            continue
        m = Marker()
        m.header.frame_id, m.header.stamp = frame, stamp
        m.ns, m.id, m.type, m.action = "cameras", f.id, Marker.LINE_LIST, Marker.ADD
        m.pose.position.x, m.pose.position.y, m.pose.position.z = f.centre
        (m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z) = f.orientation
        m.scale.x = 0.08 * depth
        m.color.r, m.color.g, m.color.b, m.color.a = 0.2, 0.9, 0.4, 1.0
        m.points = [Point(x=x, y=y, z=z) for x, y, z in f.lines]
        out.markers.append(m)
        if cache is not None:
            cache[f.id] = (f, m)
    return out
