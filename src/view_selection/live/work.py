"""The bridge's work on its COLMAP project, without ROS: features of new keyframes, matches of
announced pairs in bounded batches, and the model at the end, with every failure skipped,
recorded (DIR/ledger.txt, report.json) and retried with a growing wait a bounded number of
times. One bad image or pair never holds up the rest: an item that failed once is tried alone
afterwards, so a batch that fails names its culprit.
"""
import time

from .. import geometry
from ..colmap.project import ColmapProject, ProjectError
from ..keyframes import continuity_pairs, pair_of
from .attempts import Attempts


class LiveWork:
    def __init__(self, project: ColmapProject, continuity=True, max_backlog=2000, max_batch_pairs=24,
                 max_attempts=3, log=None, backend=None, triangulation="live", refinement=None):
        """backend: what extracts and matches (register, extract, match, extracted, matched,
        has_image): the project itself (COLMAP's commands) or matching.backend's pose-guided
        one. triangulation: "live" (live/model.py: points as pairs verify, the finish writes
        them) or "colmap" (point_triangulator over the whole model at the finish).
        refinement: refinement.refiner.ModelRefinement (issue 29: the known-pose model refined,
        DIR/sparse/0 refined, DIR/sparse/unrefined kept), or None."""
        from ..matching.backend import StageClock
        from .model import LiveModel
        self.project = project
        self.refinement = refinement
        self.backend = backend or project
        if triangulation not in ("live", "colmap"):
            raise ValueError("triangulation: live or colmap, not %r" % triangulation)
        self.triangulation = triangulation
        self.clock = StageClock()
        self.continuity = continuity
        self.max_backlog, self.max_batch_pairs = int(max_backlog), max(1, int(max_batch_pairs))
        self.images = Attempts(max_attempts)
        self.pairs = Attempts(max_attempts)
        self.log = log or (lambda level, text: None)
        self.model = LiveModel() if triangulation == "live" else None
        self.fed_poses = {}        # name -> the pose the model has for it
        self.backlog_max = 0
        self.status = {}  # the last batch's figures: keyframes, images extracted and waiting, pairs
        self.deferred = 0  # pairs beyond ~max_backlog at some point, left for the finish
        self.errors = []   # the last few, for the report
        # The pose the live model takes for a keyframe (its node pose), unless a refinement that
        # runs beside the matching (refinement/local.py) attaches its own: refined poses.
        self.pose_of = lambda k, iid: geometry.world_to_camera(k.position, k.orientation)
        if hasattr(refinement, "attach"):
            refinement.attach(self)

    def error(self, text):
        self.log("error", text)
        self.errors.append({"at": time.time(), "error": text})
        del self.errors[:-20]

    # -- running COLMAP on a batch, with the culprit found --------------------------------------
    def _attempt(self, items, run, done, attempts, kind, ledger_kind, budget=None):
        """Runs `run(items)`; the items `done()` does not list afterwards failed; returns them.

        When the run itself failed (COLMAP exited non-zero) with several items, each half is
        tried on its own, so one bad item costs its neighbours nothing (about 2 log2 n runs). The
        halving has a budget of runs (2 log2 n + 2): when COLMAP fails on everything, the rest are
        recorded as failed without running. A run that timed out is not halved: a hung COLMAP
        would cost a timeout per half."""
        if budget is None:
            budget = [2 * max(1, len(items) - 1).bit_length() + 2]
        error, timed_out = None, False
        if budget[0] <= 0:
            error = "not tried: COLMAP failed on the whole batch"
        else:
            budget[0] -= 1
            try:
                run(items)
            except ProjectError as e:
                error, timed_out = str(e), getattr(e, "timed_out", False)
                self.error(error)
        now = done()
        for i in items:
            if i in now:
                attempts.succeeded(i)
        failed = [i for i in items if i not in now]
        if error is not None and len(failed) > 1 and not timed_out and budget[0] > 0 and not self.project.cancelled:
            half = len(failed) // 2
            return (self._attempt(failed[:half], run, done, attempts, kind, ledger_kind, budget) +
                    self._attempt(failed[half:], run, done, attempts, kind, ledger_kind, budget))
        default = error or ("no features were extracted (an image that cannot be read?)" if kind == "image"
                            else "no two-view geometry was written for it")
        errors = getattr(self.backend, "errors", None) or {}
        for i in failed:
            reason = errors.get(i, default)
            if attempts.failed(i, reason):
                label = i if isinstance(i, str) else "%s %s" % i
                self.project.ledger(ledger_kind, [label])
                self.error("%s %s skipped after %d attempts: %s" % (kind, label, attempts.failures[i], reason))
        return failed

    # -- features ----------------------------------------------------------------------------
    def extract(self, keyframes):
        """Features of the keyframes whose images are there, that have none and are due.
        Returns how many were tried."""
        self.backend.register(keyframes)
        done = self.backend.extracted()
        todo = [k for k in keyframes if k.name not in done and self.backend.has_image(k.name) and self.images.due(k.name)]
        self.status.update(keyframes=len(keyframes), images_extracted=len(done), images_waiting=len(todo))
        if not todo:
            return 0
        by_name = {k.name: k for k in todo}
        self._attempt([k.name for k in todo], lambda names: self.backend.extract([by_name[n] for n in names]),
                      self.backend.extracted, self.images, "image", "skipped-image")
        for warning in getattr(self.backend, "warnings", None) or []:
            self.log("warn", warning)
        return len(todo)

    # -- matches -----------------------------------------------------------------------------
    def wanted_pairs(self, keyframes, pairs):
        """The announced pairs (names) plus, with continuity, each keyframe with the one before."""
        wanted = {pair_of(a, b) for a, b in pairs}
        if self.continuity:
            wanted |= set(continuity_pairs(keyframes))
        return wanted

    def match(self, keyframes, pairs, limit=None):
        """Matches at most `limit` (~max_batch_pairs) of the wanted pairs not matched yet whose
        images have features and that are due; True when more are waiting."""
        limit = self.max_batch_pairs if limit is None else limit
        backlog = sorted(self.wanted_pairs(keyframes, pairs) - self.backend.matched())
        have = self.backend.extracted()
        backlog = [p for p in backlog if p[0] in have and p[1] in have and not self.pairs.given_up(p)]
        self.backlog_max = max(self.backlog_max, len(backlog))
        self.status.update(backlog_pairs=len(backlog), pairs_matched=len(self.backend.matched()))
        if len(backlog) > self.max_backlog:
            self.deferred = max(self.deferred, len(backlog) - self.max_backlog)
            self.log("warn", "%d pairs wait (~max_backlog %d): the rest are matched at the finish"
                     % (len(backlog), self.max_backlog))
            backlog = backlog[:self.max_backlog]
        due = [p for p in backlog if self.pairs.due(p)]
        if not due:
            return False
        self._attempt(due[:limit], self.backend.match, self.backend.matched, self.pairs, "pair", "skipped-pair")
        return len(due) > limit

    # -- the live model ----------------------------------------------------------------------
    def feed_model(self, keyframes, final=False):
        """The live model takes the keyframes' poses (new ones, and corrected ones) and the
        verified pairs it does not have yet, and triangulates the tracks that changed; returns
        how many. Also after a restart: the database's pairs all come in once."""
        from .. import geometry
        from ..colmap.model import CAMERA_MODELS
        m = self.model
        with self.project.db() as d:
            ids, cams, cameras = d.image_ids(), d.image_cameras(), d.cameras()
            with_features = {ids[n] for n in d.images_with_features() if n in ids}
            for k in keyframes:
                iid = ids.get(k.name)
                if iid is None:
                    continue
                pose = (k.position, k.orientation)
                known = m.images.get(iid)
                if known is not None and self.fed_poses.get(k.name) == pose and (
                        len(known.keypoints) or iid not in with_features):
                    continue
                q, t = self.pose_of(k, iid)
                mid, w, h, params = cameras[cams[iid]]
                keypoints = d.keypoints(iid) if (known is None or not len(known.keypoints)) else known.keypoints
                m.add_image(iid, k.name, cams[iid], (CAMERA_MODELS[mid][0], w, h, params), q, t, keypoints)
                self.fed_poses[k.name] = pose
            for (a, b), n in d.inlier_counts().items():
                if n > 0 and (a, b) not in m.matched_pairs and a in m.images and b in m.images:
                    m.add_matches(a, b, d.matches(a, b, "two_view_geometries"))
        changed = m.update(final=final)
        self.status.update(points=len(m.points), tracks=len(m.members))
        return changed

    def refine_in_background(self):
        """The bridge's worker loop, after a batch: a refinement that runs beside the matching
        (refinement/local.py) polls its run and starts the next; True while one runs."""
        step = getattr(self.refinement, "step", None)
        return bool(step()) if step is not None and self.model is not None else False

    def skipped(self, all_failed=False):
        """What was given up (with all_failed: also what failed and was not retried yet)."""
        images, pairs = self.images.skipped(all_failed), self.pairs.skipped(all_failed)
        return {"images": images, "pairs": [dict(s, item="%s %s" % s["item"]) for s in pairs]}

    # -- the model ---------------------------------------------------------------------------
    def build_model(self, keyframes, final_pairs, model="known_poses", seed=0):
        """What is left of `final_pairs` (names) extracted and matched, then the model; returns
        the report's model part. The bridge's finish and colmap_from_selection share it.
        Items given up are left out and listed; a keyframe without features or image is not in
        the model, and the report says which."""
        import os
        from ..colmap import model as colmap_model
        from .. import geometry
        from ..evaluation.trajectory import ate_rmse
        project = self.project
        final = sorted({pair_of(*p) for p in final_pairs})
        extra = sorted(set(continuity_pairs(keyframes)) - set(final)) if self.continuity else []
        with open(os.path.join(project.root, "pairs.txt.tmp"), "w") as f:  # COLMAP's match list
            f.write("".join("%s %s\n" % p for p in final))
        os.replace(os.path.join(project.root, "pairs.txt.tmp"), os.path.join(project.root, "pairs.txt"))
        # Everything due now, in one run each (halved where a run fails): the finish does not
        # wait for backoffs, and what fails now is reported as skipped.
        for attempts in (self.images, self.pairs):
            attempts.not_before.clear()
        import time
        phases, t0 = {}, time.monotonic()
        made = None  # the live model written, when it is
        self.extract(keyframes)
        phases["extraction"], t0 = time.monotonic() - t0, time.monotonic()
        self.match(keyframes, final, limit=len(final) + len(extra) + 1)
        phases["matching"], t0 = time.monotonic() - t0, time.monotonic()
        missing = [k.name for k in keyframes if not project.has_image(k.name)]
        extracted = project.extracted()
        matched = project.matched()
        with project.db() as d:
            featureless = sorted(d.images_without_keypoints())
        wanted = set(final) | set(extra)
        out = {"keyframes": len(keyframes), "images_missing": missing,
               "images_without_features": [k.name for k in keyframes if k.name not in extracted and k.name not in missing],
               "images_with_no_features": featureless,
               "final_pairs": len(final), "continuity_pairs": len(extra), "pairs_matched": len(matched),
               "final_pairs_matched": len(set(final) & matched), "pairs_wasted": len(matched - wanted),
               "pairs_verified": project.verified_count(), "model": model, "skipped": self.skipped(all_failed=True)}
        if model == "mapper":
            path = project.mapper_model(seed)
            mapped = colmap_model.read_model(path).image_by_name()
            by_name = {k.name: k for k in keyframes}
            common = [n for n in mapped if n in by_name]
            out["ate_rmse"] = ate_rmse([geometry.centre_of(mapped[n].qvec, mapped[n].tvec) for n in common],
                                       [by_name[n].position for n in common])
            out["ate_images"] = len(common)
        else:
            have = [k for k in keyframes if k.name not in missing]
            if len(have) < 2:
                raise ProjectError("%d of %d keyframes have their image in %s: a model needs at least 2 "
                                   "(the node keeps earlier keyframes' images only with ~save_keyframe_images)"
                                   % (len(have), len(keyframes), project.images))
            if self.model is not None:
                with self.clock.measure("triangulation", 1):
                    out["tracks_triangulated_at_finish"] = self.feed_model(keyframes, final=True)
                phases["triangulation"], t0 = time.monotonic() - t0, time.monotonic()
                with project.db() as d:
                    ids = d.image_ids()
                made = self.model.to_model([ids[k.name] for k in have if k.name in ids])
                path = project.write_model(made)
                phases["writing"], t0 = time.monotonic() - t0, time.monotonic()
                if out["pairs_verified"] == 0:
                    out["model_error"] = "no pair verified: the model holds the keyframes' poses and no points"
                    self.error(out["model_error"])
            elif out["pairs_verified"] == 0:
                out["model_error"] = "no pair verified: the model holds the keyframes' poses and no points"
                self.error(out["model_error"])
                path = project.poses_only_model(have)
            else:
                try:
                    path = project.known_pose_model(have)
                except ProjectError as e:
                    if project.deadline is not None or project.cancelled:
                        raise  # out of time at shutdown: the model written before stays
                    out["model_error"] = "%s: the model holds the keyframes' poses and no points" % e
                    self.error(out["model_error"])
                    path = project.poses_only_model(have)
        if self.refinement is not None and model != "mapper" and "model_error" not in out:
            out["refinement"] = self.refinement.apply(project, path)  # issue 29: sparse/0 refined
            made = None  # the statistics are the refined model's, read from sparse/0
            phases["refinement"], t0 = time.monotonic() - t0, time.monotonic()
        out["model_path"] = path
        out.update((made if made is not None else colmap_model.read_model(path)).statistics())
        phases["statistics"] = time.monotonic() - t0
        out["finish_phases"] = {k: round(v, 3) for k, v in phases.items()}
        out["waste_ratio"] = out["pairs_wasted"] / out["pairs_matched"] if out["pairs_matched"] else 0.0
        return out
