"""The whole model's poses refined while the recording goes on, by the epipolar stage alone
(issue 34: a refined model at every length).

The finish's refinement has a few seconds (refiner.FINISH_MAX_SECONDS). On a 10-minute walk's
2,500 keyframes that is a few epipolar iterations and one or two of the bundle adjustment: the
odometry's drift came back at 0.21-0.82x. The epipolar stage (refine_model --epipolar-only: the
poses adjusted to the verified matches' epipolar geometry and the SLAM's relative motion, no
points) costs 0.3 s an iteration at that size, and its iterations add up from one run to the
next. Measured offline on the other walk's 10-minute project (528 mm odometry): 5 iterations
107 mm, then 5 more from there 69 mm (10 from the start: 64 mm); the finish's 5 s from those
poses 33-38 mm, from the odometry's 255 mm.

So while the recording goes on, runs of refine_model --epipolar-only on the live model (every
keyframe movable) start from the poses the last run reached (a keyframe that came since: its
node pose moved by the correction of the nearest keyframe before it, refinement/local.py
`corrected`), measured against the node's poses (--reference: the priors are the SLAM's motion,
and the result stays in its frame). A run starts when the verified pairs grew since the last one,
the runs' CPU (the child's, by wait4, and the Python that prepares it) stays within `cpu_share`
of a core over the session (a run may overspend; the next waits until that is paid back), and
the live model has grown past what the finish refines to convergence by itself
(finish_converges: about a minute's walk; before that the runs' poses would not be used). The
live model is not touched: its points stay at the node's poses, and the pose-guided matching
uses those.

The finish (`apply`) waits a moment for a run under way (not when the last run took longer than
that), then, where the last run found the node's poses off the matches' epipolar geometry
(OFF_RATIO) and the finish's budget would not refine the model to convergence from them
(finish_converges: a short session's finish does, and from the runs' poses it did worse), and
the runs took at least half the keyframes (MIN_TAKEN_SHARE), gives the finish's refinement
(refiner.ModelRefinement) the runs' poses to start from: the live model at them, its points
carried along; corrections are reported against the node's poses, and sparse/unrefined stays the
model at them. A keyframe whose node pose moved since a run took it (a loop closure's corrected
path) is predicted again from its new node pose.
"""
import bisect
import copy
import os
import resource
import shutil
import tempfile
import time


from ..colmap import model as colmap_model
from . import refiner
from .local import _Run, node_poses, predicted, same_pose


# The finish starts from the runs' poses only where the node's poses are off the matches'
# epipolar geometry: their median Sampson distance more than this many times what the last run
# reached. Near-exact poses (a rendered sequence's, a motion-capture system's) are within the
# noise of it, and from them the stage alone only adds its floor (the module's docstring).
OFF_RATIO = 2.0


def process_cpu():
    """[s] This process's CPU and that of its children that ended and were waited for."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


# The finish starts from the runs' poses only where its own budget would not refine the model to
# convergence from the node's: where it does not pay for CONVERGED_ITERATIONS adjustment
# iterations at ADJUSTMENT_SECONDS_PER_OBSERVATION a matched observation each. Measured on the
# built-in walk's minute on odometry (246 keyframes, 92,341 matched observations): the finish
# from the node's poses made 32 iterations in its 5 s (4.4 s of adjustment, one thread: 1.5 us an
# observation an iteration) and reached 2.8 mm; from the runs' poses of the same session (50.5 mm
# against the node's 70.6) it reached 23.6 mm, in a basin its adjustment did not leave (18.9 with
# its own epipolar stage first). Over six live runs of that minute the finish from the runs' poses
# gave 2.9-23.4 mm, from the node's 2.7-4.2. At 10 minutes (700,000-860,000) the finish makes
# 1-4 iterations and the runs' poses are what refines the model (docs/live.md).
ADJUSTMENT_SECONDS_PER_OBSERVATION = 1.5e-6
CONVERGED_ITERATIONS = 20

# And only where the runs took at least this share of the keyframes at their present node poses:
# the rest are predicted from the nearest one's correction, which does not follow the drift
# after it. On the other walk's 30 minutes the runs stopped at 864 of 7,474 keyframes (the
# bridge's own work was over ~refine_poses_live_bridge_cpu); from their poses the finish gave
# 884.8 mm against the odometry's 892.7, and since refine_model runs from start poses whatever its
# budget (to give the model at them), it read and wrote for 5.8 s and began nothing: ready 12.1 s
# after the bag, where the finish from the node's poses is not started (5.2 s). At 10 minutes the
# last run took 1,810-2,136 of 2,500.
MIN_TAKEN_SHARE = 0.5

# A run moves at most this many pose blocks (refine_model --epipolar-max-blocks): past it the
# keyframes move in runs of consecutive ids, each rigidly. The stage's sparse Cholesky
# factorisation is what grows with the session: on the other walk's 30-minute project (7,600
# keyframes, from the node's poses, one thread) 10 iterations took 17.9 s with a block a keyframe
# (898.5 -> 371.9 mm) and 5.7 s with 2,000 blocks (226.4 mm); 30 iterations 44.9 s (273.0 mm)
# and 14.7 s (120.4 mm); 1,000 blocks were cheaper (10.6 s) and worse (208.2 mm). Sessions of
# up to 2,000 keyframes (about 10 minutes) are not affected.
MAX_BLOCKS = 2000


def finish_converges(max_seconds, matched):
    """Whether a finish of `max_seconds` (0: no limit) refines a model of `matched` matched
    observations to convergence from the node's poses (the constants above)."""
    return max_seconds <= 0 or CONVERGED_ITERATIONS * ADJUSTMENT_SECONDS_PER_OBSERVATION * matched <= max_seconds


class BackgroundPoses:
    """The runs of the epipolar stage beside the matching (the module's docstring) and the
    finish that starts from their poses; LiveWork's `refinement` (step, apply)."""

    def __init__(self, finish, cpu_share=0.07, iterations=10, matches_per_pair=32, max_seconds=60.0,
                 finish_wait=1.0, clock=time.monotonic, charge=None, process_share=None):
        """finish: the finish's refiner.ModelRefinement (its options, tool and log are the runs'
        too). cpu_share: [cores] the runs' average CPU over the session. iterations: Ceres
        iterations a run makes at most. matches_per_pair: what a run is given of each verified
        pair's matches (the stage uses 8 of them). max_seconds: a run's own budget. finish_wait:
        [s] how long the finish waits at most for a run under way before it stops it (none when
        the last run says it will not end in time: finish_waits). clock: the session's
        time [s]. charge: None (the bridge) counts a run's measured CPU against the budget; a
        replay passes a function of the run's history entry (None for a run that gave nothing)
        giving the CPU seconds to count instead, so that its runs do not depend on the machine.
        process_share: [cores] or None: a run starts only while the whole process (its own CPU and
        its ended children's: the bridge's extraction, matching and runs) has used less than this
        since the first step, so the runs take only what the bridge's other work leaves under it."""
        self.finish_refinement = finish
        self.log = finish.log
        self.cpu_share, self.iterations = float(cpu_share), int(iterations)
        self.matches_per_pair, self.max_seconds = int(matches_per_pair), float(max_seconds)
        self.matches = refiner.SampledMatches(self.matches_per_pair)  # each verified pair's, kept between runs
        self.finish_wait = float(finish_wait)
        self.clock = clock
        self.charge = charge
        self.process_share = None if process_share is None else float(process_share)
        self.process_cpu_then = None  # the process's CPU at the first step [s]
        self.work = None
        self.poses = {}          # image id -> (qvec, tvec) the last run reached, (centre, orientation) of the node then
        self.ids = []            # sorted image ids of self.poses
        self.running = None
        self.started_at = None
        self.cpu_seconds = 0.0
        self.runs = 0
        self.failures = 0
        self.yielded = 0         # runs made nicer while the matching was behind (step)
        self.pairs_then = 0      # verified pairs when the last run started
        self.moved = 0           # of the images a run took, those the node moved since (start_poses)
        self.history = []        # per run: keyframes, iterations, status, cpu, seconds, Sampson before/after

    def attach(self, work):
        """LiveWork's hook; the live model keeps the node's poses (no pose_of)."""
        self.work = work

    # -- the poses -----------------------------------------------------------------------------
    def _node_poses(self):
        return node_poses(self.work)

    def start_poses(self, node=None):
        """{image id: (qvec, tvec)}: where the next run (or the finish) starts, for every image
        with a node pose: the last run's pose while its node pose is the one it started from
        (local.same_pose), else the node pose moved by the correction of the nearest image before
        it that has one (after it, for the first ones); where the node moved every image a run
        took, by the nearest one's correction all the same. Empty before a run took any."""
        if not self.poses:
            return {}
        node = self._node_poses() if node is None else node
        current = [i for i in self.ids if same_pose(self.poses[i][1], node.get(i))]
        self.moved = len(self.ids) - len(current)
        out = {}
        for iid, pose in node.items():
            taken = self.poses.get(iid)
            if taken is not None and same_pose(taken[1], pose):
                out[iid] = taken[0]
                continue
            out[iid] = predicted(current or self.ids, self.poses.get, iid, pose)
        return out

    # -- the worker loop's step ----------------------------------------------------------------
    def allowance(self):
        """CPU seconds the runs may still spend: cpu_share of the session's time so far, less what
        they spent; no more than what the process as a whole has left of process_share."""
        if self.started_at is None:
            self.started_at = self.clock()
            self.process_cpu_then = process_cpu()
        elapsed = self.clock() - self.started_at
        left = self.cpu_share * elapsed - self.cpu_seconds
        if self.process_share is not None:
            left = min(left, self.process_share * elapsed - (process_cpu() - self.process_cpu_then))
        return left

    def step(self, behind=False):
        """Polls the run under way (its poses taken once it ended) and starts the next when the
        verified pairs grew and the budget allows; returns quickly. True while a run is under way.
        behind: the bridge's matching fell behind (LiveWork.behind): the run under way is made
        nicer (local.YIELD_NICE) and none starts, so that the matching catches up first."""
        if self.work is None or self.work.model is None:
            return False
        if self.running is not None:
            run = self.running
            if run.overdue():
                self.running = None
                self.failures += 1
                self.log("warn", "the background refinement of the poses did not end within %.0f s and was killed"
                         % run.timeout)
                return False
            if not run.poll():
                if behind and run.yield_cpu():
                    self.yielded += 1
                return True
            self._finish_run(run)
            self.running = None
        if behind:
            return False
        live = self.work.model
        pairs = len(live.matched_pairs)
        if pairs <= self.pairs_then or pairs < 2 or self.allowance() <= 0:
            return False
        if finish_converges(self.finish_refinement.options.max_seconds, len(live.parent)):
            return False  # the finish refines it to convergence by itself, from the node's poses
        if sum(1 for i in live.images if live.by_image.get(i)) < 3:
            return False
        self.pairs_then = pairs
        self._start()
        return self.running is not None

    def _start(self):
        work, t0 = self.work, time.process_time()
        folder = tempfile.mkdtemp(prefix=".poses_", dir=os.path.join(work.project.root, "sparse"))
        try:
            node = self._node_poses()
            at_node = work.model.to_model()  # the live model is at the node's poses
            refiner.write_poses(at_node, {}, os.path.join(folder, "reference"))
            start = self.start_poses(node)
            if start:  # the last run's poses; the points stay (the stage uses only their depths)
                for iid, (qv, tv) in start.items():
                    im = at_node.images.get(iid)
                    if im is not None:
                        at_node.images[iid] = colmap_model.Image(iid, qv, tv, im.camera_id, im.name, im.xys,
                                                                 im.point3D_ids)
            colmap_model.write_model(at_node, os.path.join(folder, "input"), binary=True)
            # Without the pairs' rotations (refine_model's rotations' start): adopted by every run
            # of the 30-minute walk (some keyframe always turned by 5 degrees), the averaged
            # rotations (about a degree off) chained the steps again each time and undid what the
            # runs had corrected: 1,005 mm at the finish against 585 without (docs/design.md).
            matches = os.path.join(folder, "matches.bin")
            self.matches.write(work.project.database, matches)
            options = copy.copy(self.finish_refinement.options)
            options.threads, options.max_seconds = 1, self.max_seconds
            options.timeout = 4.0 * self.max_seconds + 30.0
            args = refiner.refine_model_command(refiner.find_refine_tool(self.finish_refinement.tool),
                                                os.path.join(folder, "input"), os.path.join(folder, "output"),
                                                os.path.join(folder, "report.json"), options,
                                                reference=os.path.join(folder, "reference"), matches=matches)
            args += ["--epipolar-only", "--epipolar-iterations", str(self.iterations),
                     "--epipolar-max-blocks", str(MAX_BLOCKS)]
            proc = refiner.start_refine_model(args, getattr(work.project, "log_path", None))
        except (OSError, refiner.RefinementError, colmap_model.ModelError, KeyError, ValueError) as e:
            shutil.rmtree(folder, ignore_errors=True)
            self.failures += 1
            self.log("warn", "the background refinement of the poses could not start: %s" % e)
            self.cpu_seconds += self.charge(None) if self.charge is not None else time.process_time() - t0
            return
        self.running = _Run("poses", sorted(at_node.images), [], folder, proc, node, set(),
                            time.process_time() - t0, self.max_seconds, options.timeout)

    def _finish_run(self, run):
        """The run's poses taken for the images whose node pose did not move meanwhile."""
        t0 = time.process_time()
        cpu = 0.0
        entry = None
        try:
            cpu = run.rusage.ru_utime + run.rusage.ru_stime if run.rusage is not None else 0.0
            if run.status != 0:
                raise refiner.RefinementError("refine_model exited with %s" % run.status)
            report = refiner.read_report(os.path.join(run.folder, "report.json"))
            taken = 0
            if report.get("status") == "epipolar_only":
                images = colmap_model._read_images_bin(os.path.join(run.folder, "output", "images.bin"))
                fed = self._node_poses()
                for image in report["images"]:
                    iid = image["image_id"]
                    if not image.get("refined") or iid not in images \
                            or not same_pose(fed.get(iid), run.node.get(iid)):
                        continue  # kept its pose, or the node moved it meanwhile: predicted again
                    if iid not in self.poses:
                        bisect.insort(self.ids, iid)
                    self.poses[iid] = ((tuple(images[iid].qvec), tuple(images[iid].tvec)), run.node[iid])
                    taken += 1
            epipolar = report.get("epipolar") or {}
            self.runs += 1
            entry = {"keyframes": len(run.free), "taken": taken, "status": report.get("status"),
                     "iterations": epipolar.get("iterations"),
                     "sampson_px": [round(epipolar.get("median_sampson_input", 0.0), 3),
                                    round(epipolar.get("median_sampson_refined", 0.0), 3)],
                     "sampson_node_px": round(epipolar.get("median_sampson_reference", 0.0), 3),
                     "cpu_seconds": round(cpu, 3), "seconds": round(time.monotonic() - run.started, 3)}
            self.history.append(entry)
            del self.history[:-200]
        except (OSError, refiner.RefinementError, colmap_model.ModelError, KeyError, ValueError) as e:
            self.failures += 1
            self.log("warn", "the background refinement of the poses gave nothing: %s" % e)
        finally:
            shutil.rmtree(run.folder, ignore_errors=True)
            if self.charge is not None:
                self.cpu_seconds += self.charge(entry)
            else:
                self.cpu_seconds += cpu + run.cpu + (time.process_time() - t0)

    def wait(self, seconds):
        """Waits at most `seconds` for the run under way and takes its poses; stops it when it
        would take longer."""
        run = self.running
        if run is None:
            return
        if run.wait(seconds):
            self._finish_run(run)
        else:
            self.log("info", "the background refinement of the poses under way was stopped for the finish")
        self.running = None

    def summary(self):
        return {"runs": self.runs, "failures": self.failures, "yielded": self.yielded,
                "cpu_seconds": round(self.cpu_seconds, 3),
                "cpu_share": self.cpu_share, "process_share": self.process_share, "iterations": self.iterations,
                "keyframes_with_poses": len(self.poses), "keyframes_moved_since": self.moved,
                "last_runs": self.history[-5:]}

    def poses_summary(self):
        """One line for the bridge's diagnostics (its cost does not grow with the session)."""
        last = self.history[-1] if self.history else None
        line = "%d runs, %d keyframes, %.1f s of CPU" % (self.runs, len(self.poses), self.cpu_seconds)
        if last:
            line += "; the last: %d keyframes, median Sampson distance %.2f -> %.2f px (at the node's poses %.2f)" % (
                last["keyframes"], last["sampson_px"][0], last["sampson_px"][1], last["sampson_node_px"])
        return line + ("; one under way" if self.running is not None else "")

    # -- the finish ----------------------------------------------------------------------------
    def apply(self, project, model_path, model=None, matched=0):
        """ModelRefinement.apply's seam for the finish: the finish's refinement, from the runs'
        poses (refiner.ModelRefinement.apply start_poses); the summary of the runs in the section
        (`background`)."""
        converges = finish_converges(self.finish_refinement.options.max_seconds, matched)
        if self.running is not None:
            self.wait(0.0 if converges else self.finish_waits(project))
        start, why = {}, None
        if self.work is None or self.work.model is None or not self.poses:
            why = "no run took poses"
        elif converges:
            why = "the finish refines the model to convergence from the node's poses"
        elif not self.node_off():
            why = "the node's poses are not off the matches' epipolar geometry (OFF_RATIO)"
        else:
            start = self.start_poses()
            taken = len(self.ids) - self.moved
            if taken < MIN_TAKEN_SHARE * len(start):
                why = "the runs took %d of %d keyframes (MIN_TAKEN_SHARE)" % (taken, len(start))
                start = {}
        section = self.finish_refinement.apply(project, model_path, model, matched, start_poses=start or None)
        section["background"] = dict(self.summary(), started_from=bool(start), finish_converges=converges)
        if why:
            section["background"]["not_started_from_because"] = why
        return section

    def finish_waits(self, project):
        """[s] How long the finish waits for the run under way: finish_wait at most, a quarter of
        what is left at shutdown, and nothing when the last run took longer than the time this one
        has left would allow (at 2,500 keyframes a run takes about 10 s: a wait of 1 s then
        rarely ended with its poses, and made one finish 10.4 s after the bag, a second late)."""
        wait = self.finish_wait
        if project.deadline is not None:  # at shutdown: a quarter of what is left at most
            wait = min(wait, max(0.0, (project.deadline - time.monotonic()) / 4))
        last = self.history[-1]["seconds"] if self.history else None
        if self.running is not None and last is not None \
                and last - (time.monotonic() - self.running.started) > wait:
            return 0.0
        return wait

    def node_off(self):
        """Whether the last run found the node's poses off the matches' epipolar geometry (OFF_RATIO)."""
        last = next((h for h in reversed(self.history) if h["taken"]), None)
        return last is not None and last["sampson_node_px"] > OFF_RATIO * last["sampson_px"][1]

