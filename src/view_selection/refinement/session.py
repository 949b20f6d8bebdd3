"""A selection (select_views or a node's ~export) replayed into LiveWork keyframe by keyframe, as
colmap_bridge's worker loop sees a recording, without ROS: the features and matches of what has
arrived, the live model fed, the refinement beside the matching stepped, and the finish. For the
tests and the benchmark of the refinement while the recording goes on (refinement/local.py).

The session's clock is the recording's: the keyframes' stamps. The refinement's CPU budget
(LocalRefinement.cpu_share of a core) is counted against it, as the bridge counts it against the
wall clock of a recording played at 1x; every run is waited for before the next keyframe comes.
The windows and whole-model runs of refinement/local.py count the CPU they measured, so which of
them run depends on the machine. The runs of the epipolar stage (refinement/background.py) are
counted at `poses_run_cpu` instead of what they measured, so that a replay gives the same runs
whatever the machine and its load: measured, a first test on a cold machine made fewer runs, and
their poses came out at 15.7 mm against 10.6 mm in four runs on a warm one.
"""
import os
import shutil
import time

from ..colmap.project import ColmapProject
from ..export_folder import ExportFolder
from ..keyframes import pair_of
from ..live.work import LiveWork
from ..matching.backend import PoseGuidedBackend
from ..matching.loops import LoopOptions
from .background import BackgroundPoses
from .local import LocalRefinement
from .refiner import FINISH_MAX_SECONDS, ModelRefinement, RefinementOptions


def poses_run_cpu(entry):
    """The CPU seconds a replay counts for a run of the epipolar stage (its history entry, None
    for one that gave nothing): refine_model's start, reading and writing, 0.2 s, and 30 us a
    keyframe an iteration; measured on the built-in 20 s loop, 0.205 s for 12 keyframes and 5
    iterations, 0.221 s for 56 and 10 (one thread, this machine's kind)."""
    if entry is None:
        return 0.2
    return 0.2 + 3e-5 * entry["keyframes"] * (entry.get("iterations") or 0)


class Replay:
    """colmap_bridge's work on `export` into the project folder `out` (replaced), at its
    defaults: the pose-guided matcher, live triangulation, the finish's refinement within
    FINISH_MAX_SECONDS, and the refinement beside the matching (poses_live: the bridge's
    default, refinement/background.py; else refine_live: refinement/local.py)."""

    def __init__(self, export, out, refine_live=True, threads=1, log=None, refine_tool=None, batch=4, local=None,
                 poses_live=False):
        self.export = ExportFolder(export) if isinstance(export, str) else export
        self.log = log or (lambda level, text: None)
        if os.path.exists(out):
            shutil.rmtree(out)
        self.project = ColmapProject(out, "colmap", threads)
        os.makedirs(self.project.images)
        self.project.link_images(self.export.keyframes, self.export.image_root())
        self.project.open()
        self.now = 0.0  # the recording's time [s]
        self.finish = ModelRefinement(RefinementOptions(max_seconds=FINISH_MAX_SECONDS, threads=threads),
                                      tool=refine_tool, log=self.log)
        # the refinement beside the matching: the whole model's poses by the epipolar stage
        # (poses_live, background.py: the bridge's default), or windows and the whole model
        # (refine_live, local.py)
        if poses_live:
            self.local = BackgroundPoses(self.finish, clock=lambda: self.now, charge=poses_run_cpu, **(local or {}))
        else:
            self.local = LocalRefinement(self.finish, clock=lambda: self.now, **(local or {})) if refine_live else None
        self.work = LiveWork(self.project, backend=PoseGuidedBackend(self.project), log=self.log,
                             refinement=self.local or self.finish, loops=LoopOptions())
        self.batch = max(1, int(batch))
        self.seconds = {"session": 0.0, "finish": 0.0}

    def run(self, until=None):
        """The session, then the finish; returns the finish's report."""
        self.session(until)
        return self.finish_model()

    def session(self, until=None, quiet_tail=0):
        """Keyframes arrive in order, `batch` at a time (the walk's 5 keyframes a second come
        in batches of a few), each batch then extracted, matched, fed, the refinement stepped
        and its run waited for; the last `quiet_tail` keyframes without a step (they came just
        before the finish)."""
        self.keyframes = sorted(self.export.keyframes, key=lambda k: k.id)[:until]
        pairs = [pair_of(*p) for p in self.export.pairs]
        first = self.keyframes[0].stamp
        t0 = time.monotonic()
        for n in range(self.batch, len(self.keyframes) + self.batch, self.batch):
            arrived = self.keyframes[:n]
            names = {k.name for k in arrived}
            self.now = arrived[-1].stamp - first
            announced = [p for p in pairs if p[0] in names and p[1] in names]
            self.work.extract(arrived)
            while self.work.match(arrived, announced, limit=len(announced) + len(arrived)):
                pass
            self.work.feed_model(arrived)
            if self.local is not None and n <= len(self.keyframes) - quiet_tail:
                self.work.refine_in_background()
                if self.local.running is not None:
                    self.local.wait(600.0)
        self.seconds["session"] = time.monotonic() - t0

    def finish_model(self):
        """The bridge's finish on the keyframes that came: the model, refined; its report."""
        names = {k.name for k in self.keyframes}
        t0 = time.monotonic()
        report = self.work.build_model(self.keyframes, [p for p in self.export.pairs
                                                         if p[0] in names and p[1] in names])
        self.seconds["finish"] = time.monotonic() - t0
        return report
