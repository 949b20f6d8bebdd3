"""colmap_bridge's ROS node: a COLMAP 3.8 project kept current while the recording runs.

It follows a view_selection node's pair stream (~pairs, ~get_pairs), asks the node to write the
keyframe images into the project (~write_keyframe_images), extracts and matches as keyframes and
pairs come (live/work.py over colmap/project.py), and builds the model on ~finish, once no
keyframe came for ~finish_after_idle, and at shutdown within ~shutdown_budget seconds (roslaunch
sends SIGINT, then SIGTERM 15 s later and SIGKILL 2 s after that: the finish must be done by then).

Threads: rospy's for ~pairs and ~finish; one worker (`loop`) for the batches. `lock` guards the
stream's state; `work` serialises COLMAP's work on the project (a batch, or the finish). `lock` is
taken inside `work` (a batch takes the stream's changes there), never `work` inside `lock`.
"""
import os
import signal
import sqlite3
import threading
import time

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from std_srvs.srv import Trigger, TriggerResponse

from view_selection.msg import PairChanges
from view_selection.srv import GetPairs, GetSelection, WriteKeyframeImages

from .. import geometry
from ..colmap import model as colmap_model
from ..colmap.database import DatabaseError
from ..colmap.project import ColmapProject, ProjectError, Timeouts, write_json_atomically
from ..keyframes import Keyframe
from ..refinement.afterwards import RefinementAfterwards
from ..refinement.background import BackgroundPoses
from ..refinement.local import LocalRefinement
from ..refinement.refiner import FINISH_MAX_SECONDS, ModelRefinement, RefinementOptions
from ..features.sift import SiftExtractor
from ..matching.backend import PoseGuidedBackend
from ..matching.guided import GuidedOptions
from ..matching.loops import LoopOptions
from .model_topics import ModelTopics
from .stream import PairStream
from .work import LiveWork

PARAMETERS = """Parameters (private, ~name):
  project            the COLMAP project folder (required)
  node               the view_selection node (default: /view_selection, or the one node that serves
                     get_pairs when there is no /view_selection)
  colmap             the colmap executable (colmap)
  threads            COLMAP threads (-1: all cores)
  nice               niceness of the bridge and its COLMAP children (10: the node keeps priority)
  batch_period       [s] between two batches when there is nothing to do (1.0)
  poll_period        [s] between two ~get_pairs polls (2.0)
  max_backlog        pairs a batch looks at while the recording goes on; more wait for the finish,
                     counted; the finish matches every wanted pair whatever this is (2000;
                     0: everything at the finish)
  max_batch_pairs    pairs per matching run while the recording goes on (24)
  match_delay        [s] an announced pair is matched this long after it came (10): the
                     node takes some back soon after (a later keyframe is a better partner), and
                     those are then never matched; continuity and loop pairs at once, and every
                     pair once the node says its frames stopped (0: at once)
  max_attempts       tries of an image or pair that fails before it is skipped (3)
  finish_after_idle  [s] build the model once no keyframe came for this long and the node said its
                     frames stopped (its ~pair_flush_idle), again after more
                     (1.0; 0: off, only on ~finish and at shutdown; with the mapper model, 0)
  shutdown_budget    [s] the finish at shutdown must be done within this (12; roslaunch waits 15)
  model              known_poses (the keyframes at the node's poses) or mapper (COLMAP's own)
  matcher            guided (OpenCV SIFT here, matches guided by the node's poses; COLMAP's matcher
                     for the pairs whose poses disagree with the images) or colmap (COLMAP's
                     feature_extractor and matches_importer for everything) (guided)
  max_features       SIFT features per keyframe, the strongest (2048; guided)
  guided_window_deg  how far the poses may be off and still guide a pair [deg of view] (1.5; guided)
  triangulation      live (the points triangulated as pairs verify; the finish writes them) or
                     colmap (COLMAP's point_triangulator over the whole model at the finish) (live)
  node_timeout       [s] how long the finish waits for the node's ~get_selection (10)
  continuity_pairs   also match each keyframe with the one before it (true)
  loop_pairs         also match a new keyframe (one in 5 at most) with an earlier one it may revisit
                     that the poses do not pair (true): at least loop_min_gap keyframes back (60),
                     within 0.3 m + loop_drift_ratio x the path between them (0.02) and 30 deg of
                     view, the nearest whose neighbourhoods no wanted pair joins yet
                     (matching/loops.py): drift is only seen across a revisit (a 5-minute walk on
                     odometry: 347 mm ATE, refined within 5 s to 273 mm without them, 16 with them)
  colmap_timeout     [s] a COLMAP command may take this long, plus colmap_timeout_per_image for
                     each image and colmap_timeout_per_pair for each pair it works on; then it
                     is killed, and what it worked on is retried (120, 10, 5)
  refine             known_poses: refine the model (true): keyframe poses and points bundle-adjusted
                     with the intrinsics fixed, outliers filtered, points re-triangulated at the refined
                     poses (refine_model); DIR/sparse/0 is the refined model, DIR/sparse/unrefined the
                     model at the node's poses; false: sparse/0 at the node's poses
  refine_retriangulations  re-triangulations at the refined poses, each refined again (1)
  refine_max_correction_depth_ratio  a keyframe the refinement would move further than this x the
                     median depth of its points keeps the node's pose, reported (0.5)
  refine_max_correction_deg  ... or turn further than this [deg] (15)
  refine_max_seconds  [s] the refinement's time budget in a finish, reading the matches and the
                     model included: once spent, the model is what the adjustment reached by
                     then, or the epipolar stage's, or the model as it came (report.json: status
                     out_of_time, refinement.phase_seconds), so that a long session's finish
                     stays bounded; a budget that would pay for nothing (a 30-minute session's)
                     does not start refine_model at all (5; 0: no limit)
  refine_tool        the refine_model executable ("": beside this node)
  refine_live        with live triangulation: refine while the recording goes on (false): windows of
                     new keyframes with what they see held, the whole model when the budget allows;
                     the finish refines only what changed since (refinement/local.py). Off by
                     default: at 0.25 of a core it corrected a 20 s walk's drift (0.09x) but not a
                     1-minute walk's better than the finish alone, and with exact poses it moved
                     the keyframes further (median 5.8 mm against 3.3; docs/live.md)
  refine_live_cpu    [cores] the average CPU those runs may take over the session (0.25)
  refine_poses_live  with live triangulation (and refine_live off): the whole model's poses refined
                     while the recording goes on by the epipolar stage alone, each run from where the
                     last one got to, and the finish's refinement starts from them
                     (refinement/background.py) (true)
  refine_poses_live_cpu  [cores] the average CPU those runs may take over the session (0.07)
  refine_poses_live_bridge_cpu  [cores] and a run starts only while this node (with the COLMAP
                     and refine_model it ran) has used less than this on average since the first
                     keyframes (0.48: the bridge at most half a core, with room for a run's
                     overshoot and the finish; 0: no such limit)
  refine_afterwards  after a finish whose refinement stopped at refine_max_seconds (a long
                     session's), go on refining while nothing comes: refine_model without a
                     budget on sparse/unrefined with the strongest keypoints' matches (800,000 at
                     most), one thread, niced; its model replaces sparse/0 when done unless a
                     keyframe came first (report.json: refinement_afterwards) (true)
  publish_period     [s] ~points and ~cameras are sent at most once per this (0.5; 0: not published)
  camera_scale       frustum depth of ~cameras in RViz [m, scene units] (0.15: the node's ~markers'
                     frusta are 0.1 deep, so that both show where they coincide)
Publishes ~refined_path (nav_msgs/Path, latched): the refined keyframe poses (optical frame, in the
node's world frame, at the keyframes' stamps) after each refined model that moved a keyframe by more
than 1 mm or 0.05 deg; a view_selection node takes them with ~use_path_corrections and
path:=/colmap_bridge/refined_path (docs/live.md, "Refinement").
Publishes ~points (sensor_msgs/PointCloud2: x, y, z, rgb, latched) and ~cameras
(visualization_msgs/MarkerArray, latched), in the node's world frame: the live model as it grows,
the finished (refined) model after a finish (docs/live.md, "In RViz").
"""


# A finish at shutdown stops its work (extraction, matching, the live model's update, the
# refinement) this long before ~shutdown_budget is spent, to write the model as it stands and
# report.json: with roslaunch's 3 s beyond the default budget (SIGTERM at 15 s), 5 s for
# writing. Not measured at scale yet: the live_bridge test's writing phase is a few ms.
FINISH_WRITE_RESERVE = 2.0

# ~refined_path is published when a keyframe moved more than this [m, deg]: half the node's
# ~correction_min_translation and ~correction_min_rotation_deg defaults.
PATH_MIN_TRANSLATION, PATH_MIN_ROTATION_DEG = 0.001, 0.05

# How often the worker loop looks at the refinement after a finish while it runs [s].
AFTERWARDS_POLL = 1.0

# ~match_delay [s]: how long an announced pair waits before it is matched. The node takes back
# some announced pairs when a later keyframe is a better partner, few of them sooner than 6 s
# after their matching and most within 10 s (dev/waste_timing on a project's ledger; the
# rendered walks live beside a busy core: the other walk's 10 minutes, median 12.2 s, 10th
# percentile 5.7 s, 1,087 of 2,269 within 10 s; the built-in walk's 3 minutes, median 9.3 s, 10th
# percentile 7.8 s, 207 of 330 within 10 s). What it costs is the pairs announced in the last
# seconds, matched in the pause before the finish instead of during the recording (docs/live.md,
# "Pairs taken back").
MATCH_DELAY = 10.0

# A node that tells its pauses but has sent no pause since its last keyframe: the bridge
# finishes anyway after this long without keyframes [s] (the node gone mid-recording, or frames
# that stopped before reaching it). Longer than the keyframe gaps of walking round a room seen
# before (the revisit rule), so that those do not finish.
FINISH_WITHOUT_PAUSE = 30.0


def _param(name, default):
    return rospy.get_param("~" + name, default)


class Bridge:
    def __init__(self):
        self.project_dir = _param("project", "")
        if not self.project_dir:
            raise ProjectError("~project is not set: give the COLMAP project folder, e.g. _project:=/tmp/live")
        self.node = _param("node", "").rstrip("/")
        self.batch_period = float(_param("batch_period", 1.0))
        self.poll_period = float(_param("poll_period", 2.0))
        self.finish_after_idle = float(_param("finish_after_idle", 1.0 if _param("model", "known_poses") == "known_poses"
                                              else 0.0))
        self.shutdown_budget = float(_param("shutdown_budget", 12.0))
        self.model = _param("model", "known_poses")
        if self.model not in ("known_poses", "mapper"):
            raise ProjectError("~model is '%s': known_poses or mapper" % self.model)
        self.node_timeout = float(_param("node_timeout", 10.0))
        niceness = int(_param("nice", 10))
        if niceness > 0:
            os.nice(niceness)  # COLMAP, started from here, inherits it: the node keeps priority
        self.matcher = _param("matcher", "guided")
        if self.matcher not in ("guided", "colmap"):
            raise ProjectError("~matcher is '%s': guided or colmap" % self.matcher)
        timeouts = Timeouts(float(_param("colmap_timeout", 120.0)), float(_param("colmap_timeout_per_image", 10.0)),
                            float(_param("colmap_timeout_per_pair", 5.0)))
        self.project = ColmapProject(self.project_dir, _param("colmap", "colmap"), _param("threads", -1),
                                     timeouts=timeouts)
        self.project.open()
        self.backend = None
        if self.matcher == "guided":
            self.backend = PoseGuidedBackend(
                self.project, SiftExtractor(max_features=int(_param("max_features", 2048))),
                GuidedOptions(window_deg=float(_param("guided_window_deg", 1.5))))
        refinement = None
        if self.model == "known_poses" and bool(_param("refine", True)):
            defaults = RefinementOptions()
            refinement = ModelRefinement(
                RefinementOptions(retriangulations=int(_param("refine_retriangulations", defaults.retriangulations)),
                                  max_correction_depth_ratio=float(_param("refine_max_correction_depth_ratio",
                                                                          defaults.max_correction_depth_ratio)),
                                  max_correction_deg=float(_param("refine_max_correction_deg", defaults.max_correction_deg)),
                                  threads=int(_param("threads", -1)),
                                  max_seconds=float(_param("refine_max_seconds", FINISH_MAX_SECONDS))),
                tool=_param("refine_tool", "") or None, log=self._log)
            if bool(_param("refine_live", False)) and _param("triangulation", "live") == "live":
                refinement = LocalRefinement(refinement, cpu_share=float(_param("refine_live_cpu", 0.25)))
            elif bool(_param("refine_poses_live", True)) and _param("triangulation", "live") == "live":
                process_share = float(_param("refine_poses_live_bridge_cpu", 0.48))
                refinement = BackgroundPoses(refinement, cpu_share=float(_param("refine_poses_live_cpu", 0.07)),
                                             process_share=process_share if process_share > 0 else None)
        loops = None
        if bool(_param("loop_pairs", True)) and self.model == "known_poses":
            loops = LoopOptions(min_gap=int(_param("loop_min_gap", 60)),
                                drift_ratio=float(_param("loop_drift_ratio", 0.02)))
        self.work_state = LiveWork(self.project, continuity=bool(_param("continuity_pairs", True)), loops=loops,
                                   max_backlog=_param("max_backlog", 2000),
                                   max_batch_pairs=_param("max_batch_pairs", 24),
                                   match_delay=float(_param("match_delay", MATCH_DELAY)),
                                   max_attempts=_param("max_attempts", 3), log=self._log, backend=self.backend,
                                   triangulation=_param("triangulation", "live"), refinement=refinement)
        self.afterwards = None  # the refinement after a finish (refinement/afterwards.py)
        if refinement is not None and bool(_param("refine_afterwards", True)):
            self.afterwards = RefinementAfterwards(refinement, log=self._log)
        self.afterwards_shown = None  # (the finish's keyframes, report, what the model topics showed)
        # (sparse/0, the stream's change time) of a finish to refine after: started by the worker
        # loop, whose thread lives as long as the node (a child started from ~finish's thread was
        # killed when that thread ended: setpriv's parent-death signal follows the thread).
        self.afterwards_request = None
        self.world_frame = ""  # the node's, from its messages
        self.refined_path = rospy.Publisher("~refined_path", Path, queue_size=1, latch=True)
        self.model_topics = None  # ~points, ~cameras (live/model_topics.py)
        if float(_param("publish_period", 0.5)) > 0:
            self.model_topics = ModelTopics(self.project.images, lambda: self.world_frame,
                                            float(_param("publish_period", 0.5)), float(_param("camera_scale", 0.15)),
                                            log=self._log)

        self.lock = threading.Lock()        # the stream's state
        self.wake = threading.Condition(self.lock)
        self.work = threading.Lock()        # COLMAP's work on the project: one step at a time
        self.stream = PairStream()
        self.finished_at_change = None
        self.finishing = False
        self.stopping = False
        self.last_report = None
        self.sub = None
        self.node_tells_pauses = False  # read from the node's ~pair_flush_idle once it is found

        self.diagnostics = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        # On wall time: with /use_sim_time a bag's clock stops at its end, and the report
        # matters most after that.
        self.diagnostics_thread = threading.Thread(target=self.diagnostics_loop, name="diagnostics", daemon=True)
        self.diagnostics_thread.start()
        self.finish_service = rospy.Service("~finish", Trigger, self.on_finish)
        self.thread = threading.Thread(target=self.loop, name="colmap_bridge", daemon=True)
        self.thread.start()
        rospy.loginfo("colmap_bridge: project %s, pairs from %s, model %s, matcher %s%s", self.project.root,
                      self.node or "the view_selection node (looking for it)", self.model, self.matcher,
                      ", finish after %.1f s without keyframes" % self.finish_after_idle
                      if self.finish_after_idle > 0 else "")

    @staticmethod
    def _log(level, text):
        if level == "error":  # each distinct message shown, the same one again at most every 10 s
            rospy.logerr_throttle_identical(10.0, "colmap_bridge: %s" % text)
        elif level == "warn":
            rospy.logwarn_throttle_identical(10.0, "colmap_bridge: %s" % text)
        else:
            rospy.loginfo("colmap_bridge: %s", text)

    # -- the node ---------------------------------------------------------------------------
    def find_node(self):
        """~node, or /view_selection, or the one node serving view_selection/GetPairs."""
        if self.node:
            return self.node
        try:
            import rosservice
            services = rosservice.get_service_list()
        except Exception as e:  # the master's errors come in several types
            rospy.logwarn_throttle(10.0, "colmap_bridge: cannot list services: %s" % e)
            return None
        if "/view_selection/get_pairs" in services:
            found = ["/view_selection"]
        else:
            found = sorted(s[:-len("/get_pairs")] for s in services if s.endswith("/get_pairs")
                           and rosservice.get_service_type(s) == "view_selection/GetPairs")
        if len(found) == 1:
            self.node = found[0]
            rospy.loginfo("colmap_bridge: following the node %s", self.node)
            return self.node
        rospy.logwarn_throttle(10.0, "colmap_bridge: %s; set ~node" % (
            "no view_selection node is up yet" if not found else "several view_selection nodes (%s)" % ", ".join(found)))
        return None

    def on_pairs(self, msg):
        with self.lock:
            self.world_frame = msg.header.frame_id or self.world_frame
            self.stream.receive(msg)
            self.wake.notify_all()

    def sync(self):
        """Catches up through ~get_pairs (a late start, a missed message, a node restart) and
        makes sure the node writes the keyframe images into the project."""
        if not self.find_node():
            return False
        if self.sub is None:
            self.sub = rospy.Subscriber(self.node + "/pairs", PairChanges, self.on_pairs, queue_size=1000)
            # Whether the node will say when its frames stop: it does at every pause unless its
            # ~pair_flush_idle is 0 (a parameter not set is its default, 0.5 s).
            try:
                self.node_tells_pauses = float(rospy.get_param(self.node + "/pair_flush_idle", 0.5)) > 0.0
            except (KeyError, TypeError, ValueError, rospy.ROSException) as e:
                rospy.logwarn("colmap_bridge: cannot read %s/pair_flush_idle (%s): finishing on pauses of "
                              "keyframes" % (self.node, e))
                self.node_tells_pauses = False
        name = self.node + "/get_pairs"
        with self.lock:
            since = self.stream.sequence
        try:
            rospy.wait_for_service(name, timeout=1.0)
            res = rospy.ServiceProxy(name, GetPairs)(since=since)
        except (rospy.ROSException, rospy.ServiceException) as e:
            rospy.logwarn_throttle(10.0, "colmap_bridge: %s is not answering (%s); waiting" % (name, e))
            return False
        with self.lock:
            if self.stream.sequence == since:  # else ~pairs moved on meanwhile: ask again later
                self.stream.catch_up(res.sequence, res.changes)
            else:
                self.stream.need_sync = True
        if not res.keyframe_image_dir or os.path.realpath(res.keyframe_image_dir) != os.path.realpath(self.project.images):
            try:
                w = rospy.ServiceProxy(self.node + "/write_keyframe_images", WriteKeyframeImages)(
                    directory=self.project.images)
                (rospy.loginfo if w.success else rospy.logerr)("colmap_bridge: %s", w.message)
            except (rospy.ROSException, rospy.ServiceException) as e:
                rospy.logerr_throttle(10.0, "colmap_bridge: cannot ask the node to write images: %s" % e)
        return True

    def pauses_told(self):
        """Whether the node tells when its frames stop (its ~pair_flush_idle, or a `flushed`
        message seen). The caller holds `lock`."""
        return self.node_tells_pauses or self.stream.pauses_told

    # -- the work --------------------------------------------------------------------------
    def loop(self):
        last_poll = 0.0
        while not self.stopping and not rospy.is_shutdown():
            self.poll_afterwards()
            with self.lock:
                need_sync = self.stream.need_sync
            if need_sync or time.monotonic() - last_poll > self.poll_period:
                last_poll = time.monotonic()
                self.sync()
            # Due: no keyframe for ~finish_after_idle, and the node said its frames stopped
            # (its `flushed` message, once no frame came for its ~pair_flush_idle: every pair it
            # selected is announced then). While frames still come the camera is walking where
            # it has been (the revisit rule makes no keyframe there): a finish then would be
            # work thrown away (a 30-minute walk finished 126 times, 0.5 of a core). A node that
            # never tells its pauses (~pair_flush_idle 0): no pending pair, or three times as
            # long without keyframes; one that tells them but went quiet (gone, or its camera
            # stopped unseen): FINISH_WITHOUT_PAUSE seconds without keyframes.
            with self.lock:
                s = self.stream
                idle = time.monotonic() - (s.last_keyframe_time or time.monotonic())
                if self.pauses_told():
                    stopped = s.frames_paused() or idle >= FINISH_WITHOUT_PAUSE
                else:
                    stopped = s.pending_pairs == 0 or idle >= 3 * self.finish_after_idle
                due = (self.finish_after_idle > 0 and s.keyframes and idle >= self.finish_after_idle and stopped
                       and self.finished_at_change != s.last_change_time)
                # Stopped but not idle long enough yet: look again when it has been, not a whole
                # batch period later (the node's `flushed` message at its 0.5 s woke the loop,
                # which then slept 1 s: the finish began 1.6 s after the last keyframe, not 1).
                until = s.until_idle(self.finish_after_idle) if self.finish_after_idle > 0 and stopped else None
                wait = min(self.batch_period, until + 0.01) if until else self.batch_period
                if self.afterwards is not None and (self.afterwards.running is not None or
                                                    self.afterwards_request is not None):
                    wait = min(wait, AFTERWARDS_POLL)
            more = False
            if due:
                self.finish("no keyframe for %.1f s" % idle)
            else:
                more = self.batch()
            with self.lock:
                if not self.stopping and not more:
                    self.wake.wait(wait)

    def batch(self):
        """Features of new keyframes, then matches of announced pairs not matched yet; True when
        pairs are left for the next batch."""
        with self.work:
            if self.stopping:
                return False
            with self.lock:
                keyframes = self.stream.ordered_keyframes()
                changes = self.stream.take_changes()  # taken once: handed to the work below, whatever follows
                taken_back = self.stream.take_taken_back()
                # No keyframe for half of ~finish_after_idle, or the node said its frames stopped:
                # the finish may be near, and the fallbacks waiting are matched now, before it is
                # due, not in it. (Waiting for the node's `flushed` message alone, as the finish
                # does, put that run in the way: a 10-minute walk's finish began 3.5 s after its
                # last keyframe, not 1.3 s.)
                quiet = self.stream.quiet(0.5 * self.finish_after_idle)
                # The pairs within ~match_delay: once the node said its frames stopped (a node that
                # does not tell its pauses: when quiet). On the idle time alone they were matched at
                # every pause of keyframes walking where the camera had been, and at the end the
                # batch that would have matched them came after the finish had begun: a 30-minute
                # walk's finish matched 229 delayed pairs, 1.6 s.
                paused = self.stream.frames_paused() if self.pauses_told() else quiet
            # The announced pairs' changes since the last batch (issue 34: not the whole set),
            # kept by the work before anything that may fail.
            self.work_state.announce(changes)
            if not keyframes:
                return False
            try:
                self.work_state.taken_back(taken_back)
                self.work_state.extract(keyframes)
                more = self.work_state.match(keyframes, quiet=quiet, paused=paused)
                if self.work_state.model is not None:
                    with self.work_state.clock.measure("triangulation", 1):
                        self.work_state.feed_model(keyframes)
                    self.work_state.refine_in_background()  # polls, or starts a run: returns at once
                if self.model_topics:
                    self.model_topics.live(self.work_state.model)
                return more
            except (ProjectError, DatabaseError, sqlite3.Error, OSError, ValueError) as e:
                self.work_state.error("project %s: %s" % (self.project.root, e))
                return False

    def final_state(self, ask_node=True):
        """The node's final keyframes (poses as the node has them now) and pairs, or ours."""
        name = (self.node or "/view_selection") + "/get_selection"
        why = "not asked at shutdown"
        if ask_node and self.node:
            try:
                rospy.wait_for_service(name, timeout=self.node_timeout)
                s = rospy.ServiceProxy(name, GetSelection)().selection
                with self.lock:
                    self.world_frame = s.header.frame_id or self.world_frame
                keyframes = [Keyframe.from_msg(k) for k in s.keyframes]
                names = {k.id: k.name for k in keyframes}
                pairs = [(names[p.first], names[p.second]) for p in s.pairs if p.first in names and p.second in names]
                return keyframes, pairs, "the node's final selection"
            except (rospy.ROSException, rospy.ServiceException) as e:
                why = "%s did not answer: %s" % (name, e)
        with self.lock:
            return (self.stream.ordered_keyframes(), self.stream.announced_names(),
                    "the pairs announced so far (%s)" % why)

    def finish(self, why, shutting_down=False, wait=False):
        """Builds the model from the node's final selection (or, at shutdown, from what the
        stream announced) and writes report.json: the orchestration; the report, the message
        and ~refined_path are each a function of their own. Returns (ok, message). wait: a
        finish running now (the idle one) is waited for, then this one runs (~finish: the
        caller wants a model, not "busy")."""
        with self.lock:
            while wait and self.finishing and not self.stopping:
                self.wake.wait(1.0)
            if self.finishing:
                return False, "a finish is running"
            self.finishing = True
        try:
            start, cpu_start = time.monotonic(), time.process_time()
            if not shutting_down:
                self.sync()
            synced = time.monotonic()
            with self.lock:
                # What this finish is made from: the stream after its sync. Taken before it, a
                # bridge that caught up here (started late, ~finish at once) saw the stream
                # change since, finished again when idle and stopped the refinement after this
                # finish as if a keyframe had come.
                change = self.stream.last_change_time
                last_keyframe = self.stream.last_keyframe_time
            keyframes, pairs, source = self.final_state(ask_node=not shutting_down)
            asked = time.monotonic()
            if len(keyframes) < 2:
                return False, "%d keyframes: a model needs at least 2" % len(keyframes)
            rospy.loginfo("colmap_bridge: finishing (%s): %d keyframes, %d pairs from %s", why, len(keyframes),
                          len(pairs), source)
            with self.work:  # after the batch that may be running
                if self.afterwards is not None:
                    self.afterwards.stop("a finish began")
                    with self.lock:
                        self.afterwards_shown = self.afterwards_request = None
                self.project.cancelled = False
                if shutting_down:
                    self.project.deadline = start + self.shutdown_budget - FINISH_WRITE_RESERVE
                try:
                    report = self.work_state.build_model(keyframes, pairs, self.model)
                finally:
                    with self.lock:  # shutdown() may have given this finish its deadline meanwhile
                        if not self.stopping:
                            self.project.deadline = None
                shown = None
                if self.model_topics and not shutting_down:
                    shown = self.model_topics.live(self.work_state.model)  # its last update, under `work`
            self.complete_report(report, why, source, last_keyframe,
                                 timing={"start": start, "synced": synced, "asked": asked, "cpu_start": cpu_start})
            afterwards = (not shutting_down and self.afterwards is not None and "model_path" in report
                          and RefinementAfterwards.wanted(report.get("refinement")))
            if afterwards:
                report["refinement_afterwards"] = {"status": "running"}  # until it ends: then written again
            write_json_atomically(os.path.join(self.project.root, "report.json"), report)
            self.last_report = report
            if shown is not None:
                self.model_topics.finished(report, shown)  # read and shown by its own thread
            self.publish_corrections(keyframes, report)
            with self.lock:
                self.finished_at_change = change
            if afterwards:
                with self.lock:
                    self.afterwards_shown = (keyframes, report, shown)
                    self.afterwards_request = (report["model_path"], change)
                    self.wake.notify_all()
            msg = self.finish_message(report, len(keyframes))
            skipped = report["skipped"]
            (rospy.logwarn if skipped["images"] or skipped["pairs"] else rospy.loginfo)("colmap_bridge: %s", msg)
            return True, msg
        except (ProjectError, DatabaseError, sqlite3.Error, OSError, ValueError) as e:
            self.work_state.error("project %s: %s" % (self.project.root, e))
            return False, str(e)
        finally:
            with self.lock:
                self.finishing = False
                self.wake.notify_all()

    def poll_afterwards(self):
        """The worker loop's look at the refinement after the finish: stopped once the stream
        changed since that finish (a keyframe: the next finish will do it), taken when it ended:
        its model is sparse/0 now, report.json has it as `refinement_afterwards`, and
        ~refined_path and the model topics show it."""
        a = self.afterwards
        if a is None:
            return
        with self.lock:
            request, self.afterwards_request = self.afterwards_request, None
            now = self.stream.last_change_time
        if request is not None:
            model_path, change = request
            with self.work:
                if change != now:
                    a.last = {"status": "stopped", "why": "a keyframe came before it began"}
                    self._report_afterwards(None)
                elif not a.start(self.project, model_path, change):
                    self._report_afterwards(None)
            return
        if a.running is None:
            return
        changed = a.change != now
        with self.work:
            if changed:
                if a.stop("a keyframe came"):
                    self._report_afterwards(None)
                return
            ended = a.poll()
            if not ended and a.running is not None:
                return  # still running
            section = a.take() if ended else None  # else stopped at its timeout
            shown = self._report_afterwards(section)
        if section is None or shown is None:
            return
        keyframes, report, version = shown
        rospy.loginfo("colmap_bridge: refined after the finish in %.0f s (%s): %d keyframes moved (median %.3g, "
                      "max %.3g); %s replaced", section["seconds"], section["status"], section["keyframes_refined"],
                      section["translation_median"], section["translation_max"], report["model_path"])
        self.publish_corrections(keyframes, dict(report, refinement=section))
        if self.model_topics and version is not None:
            self.model_topics.finished(report, version)

    def _report_afterwards(self, section):
        """report.json written again with how the refinement after its finish ended: its section
        (the model's figures then the refined model's), or why it gave nothing. Returns what the
        finish left for it (keyframes, report, the model topics' version), or None."""
        with self.lock:
            shown, self.afterwards_shown = self.afterwards_shown, None
        if shown is None:
            return None
        report = shown[1]
        if section is not None:
            report["refinement_afterwards"] = section
            report.update(section["statistics"])
            report["refined_afterwards_at"] = time.time()
        else:
            report["refinement_afterwards"] = dict(self.afterwards.last or {"status": "stopped"})
        try:
            write_json_atomically(os.path.join(self.project.root, "report.json"), report)
        except OSError as e:
            self.work_state.error("report.json after the refinement after the finish: %s" % e)
        return shown

    def complete_report(self, report, why, source, last_keyframe, timing):
        """report.json: build_model's part, and the bridge's (the stream, the timing of the
        finish's steps, the stages' CPU, the matching paths, the last errors)."""
        done = time.monotonic()
        report["finish_phases"].update(sync=round(timing["synced"] - timing["start"], 3),
                                       selection=round(timing["asked"] - timing["synced"], 3),
                                       cpu=round(time.process_time() - timing["cpu_start"], 3))
        report.update({
            "project": self.project.root, "node": self.node, "why": why, "pairs_source": source,
            "seconds": dict(self.project.seconds, finish=done - timing["start"]),
            "seconds_from_last_keyframe": (done - last_keyframe) if last_keyframe else None,
            "stream_messages": self.stream.messages, "sequence": self.stream.sequence,
            "backlog_max": self.work_state.backlog_max, "deferred_to_finish": self.work_state.deferred,
            "errors": self.work_state.errors[-5:], "finished_at": time.time(), "matcher": self.matcher,
            "model_topics": self.model_topics.figures() if self.model_topics else None})
        stages = self.work_state.clock.summary()
        if self.backend:
            report["matching"] = self.backend.path_counts()
            stages.update(self.backend.clock.summary())
        report["stages"] = stages
        return report

    def publish_corrections(self, keyframes, report):
        """~refined_path after a refined model, when it moved a keyframe as far as a node would
        take (its defaults: 2 mm, 0.1 deg): a path that moves nothing would only make a node
        that takes it announce again, and the bridge finish again, for nothing."""
        refined = report.get("refinement", {})
        if refined.get("refined") and (refined["translation_max"] > PATH_MIN_TRANSLATION or
                                       refined["rotation_max_deg"] > PATH_MIN_ROTATION_DEG):
            self.publish_refined_path(keyframes, report["model_path"])

    @staticmethod
    def finish_message(report, keyframes):
        """The finish's one line for the log and the ~finish answer."""
        msg = ("model in %s: %s of %d keyframes, %s points, %d pairs matched (%d wasted), %.1f s after the "
               "last keyframe" % (report["model_path"], report.get("registered", 0), keyframes,
                                  report.get("points", 0), report["pairs_matched"], report["pairs_wasted"],
                                  report["seconds_from_last_keyframe"] or 0.0))
        refinement = report.get("refinement")
        if refinement and refinement.get("refined"):
            msg += "; refined: %d keyframes moved (median %.3g, max %.3g; %.2g / %.2g deg), %d kept their pose" % (
                refinement["keyframes_refined"], refinement["translation_median"], refinement["translation_max"],
                refinement["rotation_median_deg"], refinement["rotation_max_deg"],
                len(refinement["keyframes_kept"]))
        elif refinement:
            msg += "; not refined: %s" % (refinement.get("error") or refinement.get("message"))
        if report.get("model_error"):
            msg += "; " + report["model_error"]
        if report.get("pairs_lost"):
            msg += "; %d wanted pairs not in the model (report.json: pairs_lost)" % len(report["pairs_lost"])
        skipped = report["skipped"]
        if skipped["images"] or skipped["pairs"]:
            msg += "; skipped: %d images, %d pairs (%s)" % (
                len(skipped["images"]), len(skipped["pairs"]), (skipped["images"] or skipped["pairs"])[0]["error"])
        return msg

    def diagnostics_loop(self):
        """Once a second until shutdown. Whatever one message raises is logged (throttled) and
        the next one is tried: the thread must outlive any bug in its figures."""
        while not self.stopping and not rospy.is_shutdown():
            try:
                self.publish_diagnostics()
            except rospy.ROSException:
                return  # shutting down
            except Exception as e:  # noqa: BLE001: anything, so that the thread carries on
                rospy.logerr_throttle(10.0, "colmap_bridge: diagnostics: %s: %s" % (type(e).__name__, e))
            time.sleep(1.0)

    def publish_diagnostics(self, _event=None):
        self.diagnostics.publish(DiagnosticArray(header=Header(stamp=rospy.Time.now()),
                                                 status=[self.diagnostics_status()]))

    def diagnostics_status(self):
        """/diagnostics: what the project holds, the backlog, the CPU per stage, what was skipped
        (WARN) and the last error within a minute (ERROR). The worker changes its figures
        meanwhile: each is copied at once (dict(), list(): one step under the GIL) before it is
        read. Its cost does not grow with the session (dev/benchmark_diagnostics: running
        totals, nothing per pair or per keyframe)."""
        w = self.work_state
        with self.lock:
            announced, keyframes = len(self.stream.announced), len(self.stream.keyframes)
            sequence = self.stream.sequence
        status = DiagnosticStatus(name="colmap_bridge: %s" % self.project.root, hardware_id=self.node or "")
        images_skipped, pairs_skipped = w.images.given_up_count(), w.pairs.given_up_count()
        now = time.time()
        recent = [e for e in list(w.errors) if now - e["at"] < 60.0]
        figures = dict(w.status)
        if recent:
            status.level, status.message = DiagnosticStatus.ERROR, recent[-1]["error"][:200]
        elif images_skipped or pairs_skipped:
            status.level, status.message = DiagnosticStatus.WARN, "%d images, %d pairs skipped" % (
                images_skipped, pairs_skipped)
        else:
            status.level, status.message = DiagnosticStatus.OK, "backlog %d pairs" % figures.get("backlog_pairs", 0)
        values = {"keyframes": keyframes, "pairs announced": announced, "stream sequence": sequence,
                  "matcher": self.matcher}
        values.update({k.replace("_", " "): v for k, v in figures.items()})
        stages = w.clock.summary()
        if self.backend:
            stages.update(self.backend.clock.summary())
            totals = self.backend.path_totals()
            values.update({"pairs guided": totals["guided"], "pairs guided by images": totals["images"],
                           "pairs fallback": totals["fallback"], "pairs unmatched": totals["unmatched"],
                           "fallback runs": totals["fallback_runs"]})
        for stage, figures in stages.items():
            values["%s cpu [s]" % stage] = figures["cpu_seconds"]
        report = self.last_report
        if report:
            values["last model"] = "%s points, %.1f s after the last keyframe" % (
                report.get("points"), report.get("seconds_from_last_keyframe") or 0.0)
        poses = getattr(w.refinement, "poses_summary", None)
        if poses is not None:
            values["poses refined while recording"] = poses()  # a glance, as below
        if self.afterwards is not None:
            a = self.afterwards.summary()  # read without the work lock: a glance, not a record
            last = a["last"] or {}
            values["refinement after the finish"] = "running" if a["running"] else (
                "refined %s keyframes in %.0f s" % (last.get("keyframes_refined"), last.get("seconds", 0.0))
                if "keyframes_refined" in last else
                ("stopped: %s" % last["why"]) if last.get("status") == "stopped" else
                ("failed: %s" % last["error"]) if last.get("status") == "failed" else "none")
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return status

    def publish_refined_path(self, keyframes, model_path):
        """~refined_path: every keyframe of the model at its refined pose (camera-to-world, the
        optical frame), stamped with its image's stamp, in the node's world frame: the shape of a
        SLAM system's corrected path, which the node takes with ~use_path_corrections."""
        try:
            images = colmap_model.read_model(model_path).image_by_name()
        except colmap_model.ModelError as e:
            self.work_state.error("no refined path: %s" % e)
            return
        with self.lock:
            frame = self.world_frame
        msg = Path()
        msg.header.frame_id = frame
        for k in sorted(keyframes, key=lambda k: k.id):
            im = images.get(k.name)
            if im is None:
                continue
            centre, (w, x, y, z) = geometry.camera_to_world(im.qvec, im.tvec)
            p = PoseStamped()
            p.header.frame_id = frame
            p.header.stamp = rospy.Time.from_sec(k.stamp)
            p.pose.position.x, p.pose.position.y, p.pose.position.z = centre
            p.pose.orientation.w, p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z = w, x, y, z
            msg.poses.append(p)
        if msg.poses:
            msg.header.stamp = msg.poses[-1].header.stamp
            self.refined_path.publish(msg)

    def out_of_time(self):
        """The shutdown's deadline passed with a finish still running. Its in-process steps stop
        by themselves (project.check_deadline); a COLMAP command or a refine_model started before
        the deadline was set has its own, longer timeout: they are killed (the project's work
        cancelled, this process's children killed), so that the finish writes what it has."""
        with self.lock:
            if not self.finishing:
                return
        rospy.logwarn("colmap_bridge: the shutdown's budget is spent: the finish's COLMAP and refine_model are "
                      "stopped, the model is written as it stands")
        self.project.cancel()
        for pid in child_processes():
            try:
                os.killpg(pid, signal.SIGKILL) if os.getpgid(pid) == pid else os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass

    def on_finish(self, _req):
        ok, msg = self.finish("~finish called", wait=True)
        return TriggerResponse(success=ok, message=msg)

    def shutdown(self):
        """rospy's shutdown hook (SIGINT from roslaunch or Ctrl-C): the batch running now is
        cancelled at once, and the model is finished within ~shutdown_budget from what the
        stream announced (the node may be gone already)."""
        start = time.monotonic()
        if self.afterwards is not None:  # the finish's model stays
            with self.lock:
                pending, self.afterwards_request = self.afterwards_request, None
            if self.afterwards.stop("shutdown") or pending:
                self.afterwards.last = {"status": "stopped", "why": "shutdown"}
                self._report_afterwards(None)
        with self.lock:
            self.stopping = True
            self.wake.notify_all()
            finishing = self.finishing
            # A finish running now (an idle one, started without a deadline) has until the
            # budget is spent, then writes what it has.
            self.project.deadline = start + self.shutdown_budget - FINISH_WRITE_RESERVE
        timer = None
        if not finishing:
            self.project.cancel()  # a batch; a finish that is running is left to complete
        else:
            timer = threading.Timer(max(0.0, self.project.deadline - time.monotonic()), self.out_of_time)
            timer.daemon = True
            timer.start()
        self.thread.join(timeout=self.shutdown_budget)
        if timer is not None:
            timer.cancel()
        with self.lock:
            unfinished = bool(self.stream.keyframes) and self.finished_at_change != self.stream.last_change_time
        if unfinished:
            self.shutdown_budget -= time.monotonic() - start
            ok, msg = self.finish("shutdown", shutting_down=True)
            if not ok:
                rospy.logerr("colmap_bridge: no model at shutdown: %s", msg)


def child_processes():
    """The ids of this process's children (COLMAP commands, refine_model), from /proc."""
    me, out = os.getpid(), []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open("/proc/%s/stat" % entry) as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if int(fields[1]) == me:
                out.append(int(entry))
    return out


def main(argv):
    """scripts/colmap_bridge: parse, build, spin."""
    args = rospy.myargv(argv)
    if any(a in ("-h", "--help") for a in args[1:]):
        import sys
        sys.stdout.write(USAGE)
        return 0
    rospy.init_node("colmap_bridge")
    from ..stack_sampler import start_from_environment
    start_from_environment()  # development: where the time goes (VIEW_SELECTION_STACK_SAMPLES)
    import cv2
    cv2.setNumThreads(1)  # the budget: the node keeps the cores (docs/live.md)
    from ..allocator import pad_heap
    pad_heap()  # SIFT beside the features held: about a third of the CPU it takes without (allocator.py)
    try:
        bridge = Bridge()
    except (ProjectError, DatabaseError) as e:
        rospy.logfatal("colmap_bridge: %s", e)
        return 1
    rospy.on_shutdown(bridge.shutdown)
    rospy.spin()
    return 0


USAGE = """usage: rosrun view_selection colmap_bridge _project:=DIR [_name:=value ...]

Keeps a COLMAP 3.8 project current while a view_selection node runs: the keyframe images
(DIR/images), features and matches of the pairs the node announces (DIR/database.db), and at the
end the model (DIR/sparse/0, DIR/report.json). Services: ~finish (std_srvs/Trigger) builds the
model now. docs/live.md says more.

  rosrun view_selection colmap_bridge _project:=/tmp/kitchen_live
  roslaunch view_selection tum_replay.launch bag:=kitchen.bag colmap_project:=/tmp/kitchen_live

""" + PARAMETERS
