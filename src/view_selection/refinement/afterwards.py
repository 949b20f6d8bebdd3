"""The refinement after the finish (issue 34).

A long session's finish cannot refine within its seconds: at 30 minutes (5,597 keyframes, 3.66
million matches) refine_model's 5 s do not pay for one triangulation, and the model is written
at the given poses. Offline the same project refines from 957 mm to 22.9 mm in 220 s, given the
matches of every keyframe's strongest features (a fifth of them; docs/live.md). So once a finish
has written its model, colmap_bridge goes on while nothing comes: refine_model without a budget
on sparse/unrefined (the model at the node's poses) with at most `max_matches` of the strongest
keypoints' matches (refiner.strongest_matches), one thread, niced, as a child polled from the
worker loop. When it ends before anything changed, its model replaces sparse/0 (swapped in
whole: never missing or half written) and the bridge reports and shows it. A keyframe, a finish
or the shutdown stops it and removes its folder; the model the finish wrote stays.

It follows only a finish whose refinement stopped at its budget (status out_of_time): a
converged one is all there is, and one that failed or ran away would do so again.
"""
import copy
import os
import shutil
import tempfile
import threading
import time

from . import refiner
from .local import _Run
from ..colmap import durable

MAX_MATCHES = refiner.STRONGEST_MATCHES
# Below the node, the odometry and the bridge's own matching: it uses what they leave.
NICE = 10
# Killed after this long [s]: a session's refinement to convergence took 220 s at 30 minutes
# on two threads; a hung one must not hold a core for ever.
TIMEOUT = 3600.0


class RefinementAfterwards:
    """One refine_model child after a finish: start(), then poll() from the worker loop until it
    says the run ended, then take(); stop() at any time, from any thread (the shutdown's)."""

    def __init__(self, refinement, max_matches=MAX_MATCHES, timeout=TIMEOUT, log=None):
        """refinement: the finish's (refiner.ModelRefinement, or a LocalRefinement holding one):
        its options and tool are this one's, without a budget."""
        self.finish_refinement = getattr(refinement, "finish_refinement", refinement)
        self.max_matches, self.timeout = int(max_matches), float(timeout)
        self.log = log or (lambda level, text: None)
        self.running = None     # _Run
        self.change = None      # what the finish it follows was made from (the stream's change time)
        self.model_path = None
        self.matches = (0, 0)   # given, of all the verified ones
        self.counts = {"started": 0, "taken": 0, "stopped": 0, "failed": 0}
        self.last = None        # the last run's section (less its keyframes), or its status and why
        self.lock = threading.RLock()  # the child is reaped once, by poll or by stop

    @staticmethod
    def wanted(section):
        """Whether a finish's `refinement` section leaves something to do afterwards."""
        return bool(section) and section.get("status") == "out_of_time"

    def start(self, project, model_path, change):
        """Starts refining the model of the finish that wrote `model_path` (its sparse/unrefined
        beside it is the input). change: the stream's change time the finish was made from.
        Returns True when a run started."""
        with self.lock:
            self.stop("a new finish")
            unrefined = os.path.join(os.path.dirname(os.path.abspath(model_path)), "unrefined")
            folder = None
            try:
                folder = tempfile.mkdtemp(prefix=".refine_afterwards_",
                                          dir=os.path.dirname(os.path.abspath(model_path)))
                matches = os.path.join(folder, "matches.bin")
                given = refiner.write_matches(project.database, matches, max_matches=self.max_matches)
                rotations = os.path.join(folder, "rotations.bin")
                refiner.write_rotations(project.database, rotations)
                total = refiner.count_verified_matches(project.database)
                args = refiner.refine_model_command(refiner.find_refine_tool(self.finish_refinement.tool), unrefined,
                                                    os.path.join(folder, "output"),
                                                    os.path.join(folder, "report.json"), self._options(),
                                                    matches=matches, rotations=rotations)
                proc = refiner.start_refine_model(args, getattr(project, "log_path", None), nice=NICE)
            except (OSError, refiner.RefinementError, ValueError) as e:
                if folder:
                    shutil.rmtree(folder, ignore_errors=True)
                self.counts["failed"] += 1
                self.last = {"status": "failed", "error": "could not start: %s" % e}
                self.log("warn", "the refinement after the finish could not start: %s" % e)
                return False
            self.running = _Run("afterwards", (), (), folder, proc, {}, set(), 0.0, 0.0, self.timeout)
            self.change, self.model_path, self.matches = change, model_path, (given, total)
            self.counts["started"] += 1
        self.log("info", "refining the model after the finish, in the background: %d of %d matches (the "
                         "strongest keypoints'); it replaces %s when done, unless a keyframe comes first" %
                 (given, total, model_path))
        return True

    def _options(self):
        options = copy.copy(self.finish_refinement.options)
        options.max_seconds, options.threads, options.timeout = 0.0, 1, self.timeout
        return options

    def poll(self):
        """True once the run under way ended (take() then gives its result). A run past its
        timeout is stopped (running is None then). False while one runs, or when none does."""
        with self.lock:
            run = self.running
            if run is None:
                return False
            if run.poll():
                return True
            if time.monotonic() - run.started > self.timeout:
                self.stop("it ran longer than %.0f s" % self.timeout)
            return False

    def take(self):
        """The ended run's model swapped into sparse/0 and its `refinement` section (with
        `seconds` from its start and the matches it had), or None when it gave nothing (`last`
        says why). Call once poll() said True."""
        with self.lock:
            run, self.running = self.running, None
            if run is None:
                return None
            try:
                if run.status != 0:
                    raise refiner.RefinementError("refine_model exited with %s" % run.status)
                report = refiner.read_report(os.path.join(run.folder, "report.json"))
                cpu = run.rusage.ru_utime + run.rusage.ru_stime if run.rusage is not None else 0.0
                section = refiner.section_of(report, self.matches[0], cpu, time.monotonic() - run.started,
                                             self._options())
                section["matches_of"] = self.matches[1]
                if not report.get("refined"):
                    raise refiner.RefinementError(report.get("message", "not refined"))
                durable.replace_folder(os.path.join(run.folder, "output"), os.path.abspath(self.model_path))
            except (OSError, refiner.RefinementError, KeyError, ValueError) as e:
                self.counts["failed"] += 1
                self.last = {"status": "failed", "error": str(e)}
                self.log("warn", "the refinement after the finish gave nothing; %s stays: %s" % (self.model_path, e))
                return None
            finally:
                shutil.rmtree(run.folder, ignore_errors=True)
            self.counts["taken"] += 1
            self.last = {k: v for k, v in section.items() if k != "keyframes"}
            return section

    def stop(self, why):
        """Stops the run under way (its folder removed); the model the finish wrote stays. True
        when one was running."""
        with self.lock:
            run, self.running = self.running, None
            if run is None:
                return False
            run.kill()
            self.counts["stopped"] += 1
            self.last = {"status": "stopped", "why": why, "seconds": round(time.monotonic() - run.started, 3)}
        self.log("info", "the refinement after the finish stopped (%s)" % why)
        return True

    def summary(self):
        """For the diagnostics and report.json."""
        with self.lock:
            return {"running": self.running is not None, "counts": dict(self.counts), "last": self.last,
                    "max_matches": self.max_matches}
