"""The pose-guided way of filling a project's database: SIFT features extracted here (OpenCV),
pairs matched with the node's poses (guided.py), both written in COLMAP's schema; the pairs whose
poses cannot be trusted go to COLMAP's own matcher (matches_importer: brute force and RANSAC) on
the same features. A drop-in for the COLMAP way (ColmapProject.extract/match): the same
methods, the same database, the same ledger.
"""
import collections
import os
import resource
import time

import numpy as np

from ..colmap import database as db
from ..colmap.project import ProjectError
from ..features.sift import Features, SiftExtractor
from ..keyframes import pair_of
from . import guided


def _children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


class StageClock:
    """Wall and CPU seconds of a stage, our process and the COLMAP children it ran, and how many
    items it handled."""

    def __init__(self):
        self.wall = collections.defaultdict(float)
        self.cpu = collections.defaultdict(float)
        self.items = collections.defaultdict(int)

    def measure(self, stage, items):
        clock = self

        class Scope:
            def __enter__(self):
                self.t = (time.monotonic(), time.process_time(), _children_cpu())

            def __exit__(self, *exc):
                clock.wall[stage] += time.monotonic() - self.t[0]
                clock.cpu[stage] += (time.process_time() - self.t[1]) + (_children_cpu() - self.t[2])
                clock.items[stage] += items
                return False
        return Scope()

    def summary(self):
        wall, cpu, items = dict(self.wall), dict(self.cpu), dict(self.items)
        return {s: {"items": items.get(s, 0), "wall_seconds": round(wall[s], 3),
                    "cpu_seconds": round(cpu.get(s, 0.0), 3),
                    "cpu_seconds_per_item": round(cpu.get(s, 0.0) / items[s], 4) if items.get(s) else None}
                for s in sorted(wall)}


class PoseGuidedBackend:
    def __init__(self, project, extractor=None, options=None, cache_images=64, progress=None):
        """progress: called as progress(stage, done, total, unit) while images are extracted
        and pairs matched (view_selection.progress.Progress.report), or None."""
        self.project = project
        self.extractor = extractor or SiftExtractor()
        self.options = options or guided.GuidedOptions()
        self.keyframes = {}           # name -> Keyframe, with the newest poses
        self.cache = collections.OrderedDict()  # name -> Features (the last few used)
        self.cache_images = int(cache_images)
        self.errors = {}              # item -> why it failed in the last run
        self.warnings = []            # what the last run did that a user should know
        self.paths = {}               # pair -> PairResult.summary()
        self._path_totals = collections.Counter()  # path -> pairs: the diagnostics' figures, kept as they change
        self.fallback_runs = 0        # runs of COLMAP's matcher (each costs ~0.06 s CPU beside its pairs)
        self.clock = StageClock()
        self.progress = progress or (lambda stage, done, total, unit: None)

    # -- what the project has ----------------------------------------------------------------
    def register(self, keyframes):
        for k in keyframes:
            self.keyframes[k.name] = k
        self.project.register(keyframes)

    def extracted(self, refresh=()):
        return self.project.extracted(refresh)

    def matched(self, refresh=()):
        return self.project.matched(refresh)

    def has_image(self, name):
        return self.project.has_image(name)

    # -- features ----------------------------------------------------------------------------
    def extract(self, keyframes):
        """Features of the keyframes (their images are there): read, extracted and written in
        one transaction; an image that cannot be read is left out, with its reason in errors."""
        self.register(keyframes)
        self.errors, self.warnings = {}, []
        made = {}
        stop = None  # out of time: what was made is written, then it is raised
        with self.clock.measure("extraction", len(keyframes)):
            for q, k in enumerate(keyframes):
                self.progress("extracting features", q, len(keyframes), "images")
                if self.project.cancelled:
                    raise ProjectError("extraction cancelled")
                try:
                    self.project.check_deadline("extraction")
                except ProjectError as e:
                    stop = e
                    break
                try:
                    made[k.name] = self.extractor.extract_file(os.path.join(self.project.images, k.name))
                except (ValueError, OSError) as e:
                    self.errors[k.name] = str(e)
                    continue
                if not len(made[k.name]):
                    self.warnings.append("no features in %s (a blank image?): it stays in the model without points"
                                         % k.name)
            ids = self.project.catalogue().ids
            with self.project.db() as d:
                for name, features in made.items():
                    d.write_features(ids[name], *features.to_colmap())
            self.project.catalogue().features_written(made)  # after the commit
        self.progress("extracting features", len(keyframes), len(keyframes), "images")
        for name, features in made.items():
            self._remember(name, features)
        self.project.ledger("extracted", list(made))
        if stop is not None:
            raise stop
        return len(keyframes)

    def _remember(self, name, features):
        self.cache[name] = features
        self.cache.move_to_end(name)
        while len(self.cache) > self.cache_images:
            self.cache.popitem(last=False)

    def features(self, name, database):
        if name in self.cache:
            self.cache.move_to_end(name)
            return self.cache[name]
        iid = self.project.catalogue().ids[name]
        f = Features.from_colmap(database.keypoints(iid), database.descriptors(iid))
        self._remember(name, f)
        return f

    # -- matches -----------------------------------------------------------------------------
    def match(self, pairs, defer_fallback=None):
        """Each pair (name, name) guided by the poses; the ones that fall back are matched by
        COLMAP's matches_importer afterwards (match_fallback), or, with defer_fallback, handed
        to it (a callable taking the list) for a later run of several batches' fallbacks. Every
        pair matched gets its raw matches and its two-view geometry (verified, or empty) in the
        database."""
        pairs = [pair_of(*p) for p in pairs]
        self.errors = {}
        fallback, written = [], []
        stop = None  # out of time: the pairs matched so far are committed, then it is raised
        with self.clock.measure("guided_matching", len(pairs)):
            ids = self.project.catalogue().ids
            with self.project.db() as d:
                for q, (a, b) in enumerate(pairs):
                    self.progress("matching", q, len(pairs), "pairs")
                    if self.project.cancelled:
                        raise ProjectError("matching cancelled")
                    try:
                        self.project.check_deadline("matching")
                    except ProjectError as e:
                        stop = e
                        break
                    ka, kb = self.keyframes.get(a), self.keyframes.get(b)
                    if ka is None or kb is None:
                        self.errors[(a, b)] = "no pose for %s" % (a if ka is None else b)
                        continue
                    result = guided.match_pair(self.features(a, d), self.features(b, d), ka, kb, self.options)
                    self._count_path((a, b), result.summary())
                    if result.path == guided.FALLBACK:
                        fallback.append((a, b))
                        continue
                    d.write_matches(ids[a], ids[b], result.matches)
                    if result.path == guided.UNMATCHED:  # as COLMAP writes a pair with too few matches
                        d.write_two_view_geometry(ids[a], ids[b], np.zeros((0, 2), np.int64), db.DEGENERATE)
                        written.append(((a, b), 0))
                        continue
                    g = result.geometry  # estimated from the matches, in the database's pixel convention
                    d.write_two_view_geometry(ids[a], ids[b], g.inliers, db.CALIBRATED, F=g.F, E=g.E,
                                              qvec=_quaternion(g.R), tvec=g.t)
                    written.append(((a, b), len(g.inliers)))
            for pair, rows in written:  # after the commit: the catalogue holds what the database does
                self.project.catalogue().geometry_written(pair, rows)
        self.progress("matching", len(pairs), len(pairs), "pairs")
        self.project.ledger("matched", ["%s %s" % p for p, _ in written])
        if stop is not None:
            raise stop
        if fallback and defer_fallback is not None:
            defer_fallback(fallback)
        elif fallback:
            self.match_fallback(fallback)
        return len(pairs)

    def match_fallback(self, pairs):
        """The pairs (name, name) matched by COLMAP's matches_importer, in one run: the path of
        the pairs whose poses cannot be trusted."""
        with self.clock.measure("fallback_matching", len(pairs)):
            self.progress("matching by COLMAP's matcher", 0, len(pairs), "pairs")  # one run: no count between
            self.project.match(pairs)  # COLMAP's own; it writes the ledger
            self.progress("matching by COLMAP's matcher", len(pairs), len(pairs), "pairs")
        self.fallback_runs += 1

    def _count_path(self, pair, summary):
        old = self.paths.get(pair)
        if old is not None:
            self._path_totals[old["path"]] -= 1
        self.paths[pair] = summary
        self._path_totals[summary["path"]] += 1

    def path_totals(self):
        """{'guided': n, 'images': n, 'fallback': n, 'unmatched': n, 'fallback_runs': n} of the pairs
        matched so far (by the poses, by the images' geometry, by COLMAP's matcher, too few matches
        for COLMAP's to verify, and its runs), without looking at each pair
        (the diagnostics ask once a second; path_counts() formats every pair)."""
        totals = dict(self._path_totals)
        return {"guided": totals.get(guided.GUIDED, 0), "images": totals.get(guided.IMAGES, 0),
                "fallback": totals.get(guided.FALLBACK, 0), "unmatched": totals.get(guided.UNMATCHED, 0),
                "fallback_runs": self.fallback_runs}

    def path_counts(self):
        """Which path the pairs matched so far took: {'guided': n, 'images': n, 'fallback': n,
        'unmatched': n} (by the poses, by the images' geometry where the poses disagreed, by
        COLMAP's matcher, not verified: too few matches for COLMAP's), the reasons of the last
        two, the bands of the guided ones (median, 90th percentile, max [px]), and each pair's
        summary."""
        paths = dict(self.paths)  # a copy taken at once: the diagnostics timer reads it beside the work
        counts = collections.Counter(s["path"] for s in paths.values())
        bands = [s["band_px"] for s in paths.values() if s["path"] == guided.GUIDED]
        return {"guided": counts.get(guided.GUIDED, 0), "images": counts.get(guided.IMAGES, 0),
                "fallback": counts.get(guided.FALLBACK, 0), "unmatched": counts.get(guided.UNMATCHED, 0),
                "fallback_runs": self.fallback_runs,
                "fallback_pairs": {"%s %s" % p: s.get("why", "") for p, s in sorted(paths.items())
                                   if s["path"] == guided.FALLBACK},
                "unmatched_pairs": {"%s %s" % p: s.get("why", "") for p, s in sorted(paths.items())
                                    if s["path"] == guided.UNMATCHED},
                "band_px": {"median": float(np.median(bands)), "p90": float(np.percentile(bands, 90)),
                            "max": float(max(bands))} if bands else None,
                "pairs": {"%s %s" % p: s for p, s in sorted(paths.items())}}


def _quaternion(r):
    from ..geometry import quaternion_of
    return quaternion_of(np.asarray(r))
