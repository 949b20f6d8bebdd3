"""The known-pose model refined: refine_model (C++/Ceres) run as a process on a COLMAP model
folder, as the project runs COLMAP (a timeout, a clear error naming the stage, killed with its
parent), with the project's verified matches:

  1. the poses and points adjusted with the intrinsics fixed, a robust (Cauchy) loss, the SLAM's
     relative motion between consecutive keyframes as soft priors, observations beyond 4 px
     filtered, round after round;
  2. the points triangulated anew from the tracks of the matches at the refined poses: matches
     that the drifting poses rejected become points now;
  3. adjusted and filtered again; corrections measured against the SLAM poses, implausible ones
     kept at the SLAM pose; the result aligned to the SLAM poses.

Points triangulated at wrong poses are outlier observations at the right ones: an adjustment
without filtering and re-triangulation follows them (issue 29: COLMAP's bundle_adjuster made a
drifted DTU set 7.3x worse). The seam: `refine(model folder, which images stay fixed, the
database) -> the refined folder + the report's section`, with the per-keyframe corrections.
"""
import copy
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from .. import geometry
from ..colmap import durable, model as colmap_model
from ..colmap.process import Colmap, _death_signal_prefix


# The refinement's time budget in a live finish [s] (colmap_bridge's ~refine_max_seconds): the
# kitchen's takes 1.5-3 s here (25,000 observations), a 3-minute walk's (330,000) did not end in
# 120 s (docs/live.md, "Measured").
FINISH_MAX_SECONDS = 5.0

# The matches a long session's refinement is given at most, the strongest keypoints' (the one
# after the finish, afterwards.py; the finish's from the poses refined while the recording went
# on). The 30-minute walk's strongest 95 keypoints of every keyframe (791,994 of 3.66 million
# matches) refined it to 22.9 mm in 220 s on two threads; its strongest 25 (199,457) were too
# few to hold the loop (718 mm). A 10-minute walk's finish from those poses: with all 1.75
# million, one adjustment iteration in 4.3 s of its 5 (95.8 mm stayed 95.8); with 800,000, four
# (43.8 mm), its model 37,827 points against 83,368.
STRONGEST_MATCHES = 800000

# The pairs whose relative rotations refine_model is given (--rotations, write_rotations): those
# with at least this many inliers, as its epipolar stage takes a pair (epipolar_min_matches).
ROTATION_MIN_INLIERS = 15

# What refine_model's steps ask of the time left, in its own rules (src/refine/model_refinement.cpp):
# the matches' triangulation (and the epipolar stage) begins when half the time left pays for 1 us
# an observation of the matches (RefinementConfig::triangulation_seconds_per_observation); without
# it, an adjustment of the model's own points alone begins when the time left pays for 11 x 3 us an
# observation of the model (kAdjustmentAloneSolves x kSolveSecondsPerObservation). Both are
# weighed after refine_model read the model and the matches, out of the same budget; that reading
# took 0.145 us a match on a small model and 0.26-0.39 us at 30 minutes (its model included), and
# READING_SECONDS_PER_MATCH is a third of the least of them: counted as more, the rule would skip
# a refinement refine_model begins (0.15 us: one round of two iterations on the test's model).
# Where the budget pays for neither, a finish does not start refine_model (not_begun): reading a
# 30-minute session's model and counting its matches took 1.7-4.5 s of the finish to begin
# nothing. test_refinement checks that refine_model begins nothing there.
TRIANGULATION_SECONDS_PER_OBSERVATION = 1e-6
ADJUSTMENT_ALONE_SECONDS_PER_OBSERVATION = 33e-6
READING_SECONDS_PER_MATCH = 0.05e-6


class RefinementError(Exception):
    """The refinement could not run (tool missing, failed, timed out); the unrefined model stays."""


class RefinementOptions:
    """What refine_model is given (its --help says more) and how the steps run.

    retriangulations: how many times the points are triangulated anew from the matches at the
    refined poses and refined again (0: the model's own points only). max_seconds: the time
    refine_model may take before it stops with what it reached (status out_of_time; 0: no
    limit); timeout: when it is killed and the unrefined model stays."""

    def __init__(self, loss="cauchy", loss_scale=1.0, max_error=4.0, min_angle=1.5, rounds=4, iterations=100,
                 min_observations=15, max_correction_depth_ratio=0.5, max_correction_deg=15.0,
                 retriangulations=1, threads=-1, timeout=120.0, max_seconds=0.0, epipolar=True):
        self.loss, self.loss_scale, self.max_error, self.min_angle = loss, float(loss_scale), float(max_error), float(min_angle)
        self.rounds, self.iterations, self.min_observations = int(rounds), int(iterations), int(min_observations)
        self.max_correction_depth_ratio, self.max_correction_deg = float(max_correction_depth_ratio), float(max_correction_deg)
        self.retriangulations, self.threads, self.timeout = int(retriangulations), int(threads), float(timeout)
        self.max_seconds = float(max_seconds)  # refine_model's own time budget (0: none); timeout kills it
        self.epipolar = bool(epipolar)  # the epipolar stage before the first triangulation (False: --no-epipolar)

    def arguments(self):
        return ["--loss", self.loss, "--loss-scale", repr(self.loss_scale), "--max-error", repr(self.max_error),
                "--min-angle", repr(self.min_angle), "--rounds", str(self.rounds), "--iterations", str(self.iterations),
                "--min-observations", str(self.min_observations),
                "--max-correction-depth-ratio", repr(self.max_correction_depth_ratio),
                "--max-correction-deg", repr(self.max_correction_deg),
                "--retriangulations", str(self.retriangulations),
                "--threads", str(max(0, self.threads)), "--max-seconds", repr(self.max_seconds)] + \
            ([] if self.epipolar else ["--no-epipolar"])

    def to_json(self):
        return dict(vars(self))


def find_refine_tool(explicit=None):
    """The refine_model executable: `explicit`, beside the running script (rosrun's devel relay
    or the install space put the C++ tools there), the build folder beside a checkout, rosrun's
    search, or PATH."""
    candidates = [explicit] if explicit else []
    candidates.append(os.path.join(os.path.dirname(os.path.abspath(sys.argv[0])), "refine_model"))
    from ..ros_session import DEFAULT_BUILD_DIR
    candidates.append(os.path.join(DEFAULT_BUILD_DIR, "devel", "lib", "view_selection", "refine_model"))
    for c in candidates:
        if c and os.path.isfile(c) and os.access(c, os.X_OK):
            return os.path.abspath(c)
    try:
        import roslib.packages
        found = roslib.packages.find_node("view_selection", "refine_model")
        if isinstance(found, (list, tuple)):
            found = found[0] if found else None
        if found:
            return found
    except Exception:  # no ROS, or no package path: try PATH
        pass
    found = shutil.which("refine_model")
    if found:
        return found
    raise RefinementError("cannot find the refine_model tool (build the package; or give its path)")


def refine_model_command(tool, model, output, report, options, fixed=(), reference=None, matches=None,
                         progress=False, start=None, rotations=None):
    """refine_model's command line (the list of images held written beside `output`)."""
    args = [tool, "--input", model, "--output", output, "--report", report, "--quiet"] + options.arguments()
    if progress:
        args += ["--progress-interval", "1"]
    if reference:
        args += ["--reference", reference]
    if start:
        args += ["--start", start]
    if matches:
        args += ["--matches", matches]
    if rotations:
        args += ["--rotations", rotations]
    args += os.environ.get("VS_REFINE_EXTRA", "").split()  # development: more refine_model options
    if fixed:
        listing = output.rstrip("/") + ".fixed.txt"
        with open(listing, "w") as f:
            f.write("".join(n + "\n" for n in fixed))
        args += ["--fixed", listing]
    return args


def start_refine_model(args, log_path=None, nice=0):
    """refine_model (its command line, refine_model_command) started as a child that runs while
    the caller goes on: its command and output appended to `log_path`, `nice` above the caller's
    niceness, in a session of its own (Colmap._kill stops it whole), killed when the thread that
    started it ends (setpriv's parent-death signal follows the thread: start it from one that
    lives as long as the run). Returns the Popen."""
    cmd = (["nice", "-n", str(nice)] if nice else []) + list(args)
    log = open(log_path, "a") if log_path else None
    try:
        if log:
            log.write("$ %s\n" % " ".join(cmd))
            log.flush()
        return subprocess.Popen(_death_signal_prefix() + cmd, stdout=log or subprocess.DEVNULL,
                                stderr=log or subprocess.DEVNULL, start_new_session=True)
    finally:
        if log:
            log.close()


def read_report(report):
    try:
        with open(report) as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        raise RefinementError("refine_model wrote no readable report (%s)" % e)


def run_refine_model(tool, model, output, report, options, fixed=(), reference=None, log_path=None, timeout=None,
                     matches=None, progress=None, start=None, rotations=None):
    """One refine_model process; returns its report (dict). RefinementError when it cannot run,
    fails or exceeds the timeout (then it is killed). progress: called with each of its progress
    lines as it prints them (a line a second; None: they go to the log at the end, one every 10 s)."""
    args = refine_model_command(tool, model, output, report, options, fixed, reference, matches, bool(progress),
                                start, rotations)
    timeout = options.timeout if timeout is None else timeout
    log = open(log_path, "a") if log_path else None
    try:
        if log:
            log.write("$ %s\n" % " ".join(args))
            log.flush()
        try:
            proc = subprocess.Popen(_death_signal_prefix() + args, stdout=log or subprocess.DEVNULL,
                                    stderr=subprocess.PIPE, universal_newlines=True, start_new_session=True)
        except OSError as e:
            raise RefinementError("cannot run %s: %s" % (tool, e.strerror or e))
        try:
            if progress:
                err = _relay(proc, progress, max(1.0, timeout))
            else:
                _, err = proc.communicate(timeout=max(1.0, timeout))
        except subprocess.TimeoutExpired:
            Colmap._kill(proc)
            raise RefinementError("refine_model did not finish within %.0f s and was killed" % timeout)
        except BaseException:
            Colmap._kill(proc)
            raise
        if log:
            log.write(err or "")
            log.write("# exit %d\n" % proc.returncode)
    finally:
        if log:
            log.close()
    if proc.returncode != 0:
        raise RefinementError("refine_model failed (exit %d): %s" % (proc.returncode, (err or "").strip()[-500:]))
    return read_report(report)


def _relay(proc, progress, timeout):
    """Waits for `proc` as communicate() does, handing each line of its stderr to `progress` as it
    comes; returns the whole stderr. subprocess.TimeoutExpired after `timeout` seconds."""
    import threading
    lines = []

    def read():
        for line in proc.stderr:
            lines.append(line)
            progress(line.rstrip("\n"))
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    proc.wait(timeout=timeout)
    reader.join(timeout=5.0)  # the pipe ends with the process
    return "".join(lines)


def poses_only(model):
    """The same images at the same poses, without points or 2D points: what point_triangulator
    starts from."""
    out = colmap_model.Model(dict(model.cameras))
    for iid, im in model.images.items():
        out.images[iid] = colmap_model.Image(iid, im.qvec, im.tvec, im.camera_id, im.name)
    return out


def corrections(before, after):
    """Per image name present in both: the centre's move [model units] and the turn [deg]."""
    out = {}
    b = before.image_by_name()
    for name, im in after.image_by_name().items():
        if name not in b:
            continue
        c0 = np.array(geometry.centre_of(b[name].qvec, b[name].tvec))
        c1 = np.array(geometry.centre_of(im.qvec, im.tvec))
        out[name] = (float(np.linalg.norm(c1 - c0)), geometry.rotation_angle_deg(b[name].qvec, im.qvec))
    return out


def strongest_matches(data, max_matches):
    """At most `max_matches` rows of `data` (image id, keypoint, image id, keypoint): those whose
    two keypoints are both among the strongest L of their images (keypoints are stored strongest
    first), L as large as keeps them within `max_matches`. A keypoint is kept or dropped in all
    its matches alike, so that the tracks stay whole (an even share of each pair's matches breaks
    them apart). Returns (rows, L); L is None when all are kept."""
    if not max_matches or len(data) <= max_matches:
        return data, None
    weakest = np.maximum(data[:, 1], data[:, 3])
    limit = int(np.partition(weakest, max_matches)[max_matches])  # below it: at most max_matches
    return data[weakest < limit], limit


def count_verified_matches(database_path):
    """How many verified matches (two-view geometries' inliers) the database holds."""
    from ..colmap import database as cdb
    with cdb.open_database(database_path) as d:
        return int(sum(n for n in d.inlier_counts().values() if n > 0))


def count_matched_observations(database_path):
    """How many distinct observations (image id, keypoint) the database's verified matches hold:
    refine_model's count before its tracks (the live model's union-find holds them as they came)."""
    from ..colmap import database as cdb
    with cdb.open_database(database_path) as d:
        counts, m = d.verified_matches()
    first = np.repeat(counts[:, 0], counts[:, 2]) * (1 << 32) + m[:, 0]
    second = np.repeat(counts[:, 1], counts[:, 2]) * (1 << 32) + m[:, 1]
    return len(np.unique(np.concatenate([first, second])))


def write_matches(database_path, path, pairs=None, per_pair=0, max_matches=0):
    """The database's verified matches (two-view geometries' inliers) as refine_model's VSMATCH1
    file: image id and keypoint index of both sides, the ids the model's images have. `pairs`:
    only these (image id, image id) pairs (a cropped refinement, refinement/local.py), read one
    by one. `per_pair`: at most this many of each pair's, evenly spread over its list (0: all).
    `max_matches`: at most this many in all, the strongest keypoints' (strongest_matches; 0: all).
    Returns how many."""
    from ..colmap import database as cdb
    with cdb.open_database(database_path) as d:
        if pairs is None and not per_pair:
            # Every pair's, in one read (the finish's: 3.65 million matches at 30 minutes).
            counts, m = d.verified_matches()
            data = np.empty((len(m), 4), "<i4")
            data[:, 0] = np.repeat(counts[:, 0], counts[:, 2])
            data[:, 1] = m[:, 0]
            data[:, 2] = np.repeat(counts[:, 1], counts[:, 2])
            data[:, 3] = m[:, 1]
        else:
            rows = []
            wanted = sorted(d.inlier_counts().items()) if pairs is None else [(p, 1) for p in sorted(pairs)]
            for (a, b), n in wanted:
                if n > 0:
                    rows.append(_pair_rows(d, a, b, per_pair))
            data = np.concatenate(rows) if rows else np.zeros((0, 4), "<i4")
    data, _ = strongest_matches(data, max_matches)
    _write_match_file(path, data)
    return len(data)


def write_rotations(database_path, path, pairs=None):
    """The verified pairs' relative rotations (their two-view geometries', estimated from the
    pair's matches) as refine_model's VSROTAT1 file, the pairs with at least ROTATION_MIN_INLIERS
    inliers (`pairs`: only those, read one by one). Returns how many."""
    from ..colmap import database as cdb
    with cdb.open_database(database_path) as d:
        rotations = d.pair_rotations(ROTATION_MIN_INLIERS, pairs)
    _write_rotation_file(path, rotations)
    return len(rotations)


def _write_rotation_file(path, rotations):
    import struct
    with open(path, "wb") as f:
        f.write(b"VSROTAT1" + struct.pack("<Q", len(rotations)))
        f.write(b"".join(struct.pack("<ii4d", a, b, *q) for a, b, q in rotations))


def _pair_rows(database, a, b, per_pair):
    """A pair's verified matches as VSMATCH1 rows (image id, keypoint, image id, keypoint), at most
    `per_pair` of them evenly spread over its list (0: all)."""
    m = np.asarray(database.matches(a, b, "two_view_geometries"), np.int64).reshape(-1, 2)
    if per_pair and len(m) > per_pair:
        m = m[np.linspace(0, len(m) - 1, per_pair).astype(np.int64)]
    return np.stack([np.full(len(m), a), m[:, 0], np.full(len(m), b), m[:, 1]], axis=1).astype("<i4")


def _write_match_file(path, data):
    import struct
    with open(path, "wb") as f:
        f.write(b"VSMATCH1" + struct.pack("<Q", len(data)))
        f.write(memoryview(np.ascontiguousarray(data, "<i4")).cast("B"))


class SampledMatches:
    """write_matches(database, path, per_pair=N) for a caller that writes the file again and
    again as the database grows (the runs while the recording goes on, refinement/background.py):
    each pair's rows are kept from one call to the next and read again only when its inlier count
    changed (matched again); a pair that lost its geometry is dropped. The file is the one
    write_matches writes. At 30 minutes write_matches read 26,000 pairs' matches one by one for
    every run (1.9 s)."""

    def __init__(self, per_pair):
        self.per_pair = int(per_pair)
        self.pairs = {}  # (image id, image id) -> (inlier count, rows)

    def write(self, database_path, path):
        """Writes the VSMATCH1 file; returns how many matches it holds."""
        from ..colmap import database as cdb
        with cdb.open_database(database_path) as d:
            counts = {pair: n for pair, n in d.inlier_counts().items() if n > 0}
            for pair in [p for p, (n, _) in self.pairs.items() if counts.get(p) != n]:
                del self.pairs[pair]
            for pair, n in counts.items():
                if pair not in self.pairs:
                    self.pairs[pair] = (n, _pair_rows(d, pair[0], pair[1], self.per_pair))
        rows = [self.pairs[p][1] for p in sorted(self.pairs)]
        data = np.concatenate(rows) if rows else np.zeros((0, 4), "<i4")
        _write_match_file(path, data)
        return len(data)


def refine(model_dir, output, options=None, fixed=(), database=None, tool=None, log_path=None, deadline=None,
           log=None, pairs=None, reference=None, progress=None, budget_start=None, model=None, matched=0,
           start_model=None, max_matches=0):
    """Refines the model in `model_dir` into `output` (replaced only at the end; on any error
    `output` is untouched and RefinementError says why). `fixed`: image names that must not
    move. `database`: the project's database, whose verified matches the points are
    triangulated anew from (None: the model's own points only; `pairs`: only these image id
    pairs' matches). `deadline`: time.monotonic() by which it must be done. `reference`: a
    model folder with the poses the result is aligned to and corrections are measured against
    (refine_model --reference; default the input's). `progress`: called with each of
    refine_model's progress lines. `budget_start`: when options.max_seconds began to count
    (time.monotonic(); default now): the time spent since, writing the matches file included,
    comes out of refine_model's budget, so that the whole refinement keeps to it. `model`,
    `matched`: the model in `model_dir` (refined in place: `output` is `model_dir`) and the
    distinct observations of the database's matches, when the caller holds them: where what is
    left of the budget pays for nothing (not_begun), before the matches are written or after,
    refine_model is not started and the model stays as it is. `start_model`: a model folder with the
    poses the refinement starts from (refine_model --start). `max_matches`: at most this many
    of the matches, the strongest keypoints' (0: all). Returns the report's `refinement`
    section (dict)."""
    options = options or RefinementOptions()
    log = log or (lambda text: None)
    tool = find_refine_tool(tool)
    start = time.monotonic()
    parent = os.path.dirname(os.path.abspath(output))
    os.makedirs(parent, exist_ok=True)
    work = tempfile.mkdtemp(prefix=".refine_", dir=parent)
    timeout = options.timeout
    if deadline is not None:
        timeout = min(timeout, deadline - time.monotonic())
        if timeout <= 1.0:
            raise RefinementError("no time left for the refinement")
    begun = start if budget_start is None else budget_start
    in_place = model is not None and database and os.path.abspath(output) == os.path.abspath(model_dir)

    def paid_for_nothing(count):
        section = not_begun(model, matched, options, options.max_seconds - (time.monotonic() - begun), count) \
            if in_place else None
        if section is not None:
            section["matches"], section["seconds"] = count, time.monotonic() - start
            log("refinement: %s" % section["message"])
        return section

    try:
        matches, count, rotations = None, 0, None
        nothing = paid_for_nothing(0)
        if nothing is None and database and options.retriangulations > 0:
            matches = os.path.join(work, "matches.bin")
            count = write_matches(database, matches, pairs, max_matches=max_matches)
            # refine_model's epipolar stage starts from averaged rotations only where no image is held
            if options.epipolar and not fixed:
                rotations = os.path.join(work, "rotations.bin")
                write_rotations(database, rotations, pairs)
            nothing = paid_for_nothing(count)
        if nothing is not None:
            return nothing
        made = os.path.join(work, "refined")
        if options.max_seconds > 0:
            # What is left of the budget (at least a moment: refine_model then returns the model
            # as it came, with status out_of_time, and still reports its figures).
            spent = time.monotonic() - begun
            options = copy.copy(options)
            options.max_seconds = max(1e-3, options.max_seconds - spent)
        import resource
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        report = run_refine_model(tool, os.path.abspath(model_dir), made, made + ".json", options, fixed,
                                  reference=reference, log_path=log_path, timeout=timeout, matches=matches,
                                  progress=progress, start=start_model, rotations=rotations)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime + after.ru_stime) - (children.ru_utime + children.ru_stime)
        log("refinement: %s" % report["message"])
        durable.replace_folder(made, os.path.abspath(output))
        return section_of(report, count, cpu, time.monotonic() - start, options)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def section_of(report, matches, cpu, seconds, options):
    """The report's `refinement` section from refine_model's report: the per-keyframe
    corrections, their spread, the figures before and after. matches: how many it was given."""
    keyframes = []
    for im in report["images"]:
        keyframes.append({"name": im["name"], "refined": im["refined"], "kept": im["kept"] or None,
                          "weak": im.get("weak", False),
                          "translation": im["translation"], "rotation_deg": im["rotation_deg"],
                          "observations": [im["observations_input"], im["observations_refined"]]})
    moved = [k for k in keyframes if k["refined"]]
    translations = sorted(k["translation"] for k in moved)
    rotations = sorted(k["rotation_deg"] for k in moved)
    return {
        "status": report["status"], "refined": report["refined"], "message": report["message"],
        "keyframes": keyframes, "keyframes_refined": len(moved),
        "keyframes_kept": [{"name": k["name"], "why": k["kept"]} for k in keyframes if k["kept"]],
        "translation_median": translations[len(translations) // 2] if translations else 0.0,
        "translation_max": translations[-1] if translations else 0.0,
        "rotation_median_deg": rotations[len(rotations) // 2] if rotations else 0.0,
        "rotation_max_deg": rotations[-1] if rotations else 0.0,
        "points": [report["points_input"], report["points_refined"]],
        "observations": [report["observations_input"], report["observations_refined"]],
        "observations_filtered": report["observations_filtered"],
        "reprojection_error": [report["reprojection_error_input"], report["reprojection_error_refined"]],
        "rounds": report["rounds"], "iterations": report["iterations"], "passes": report["passes"],
        "retriangulations": report.get("retriangulations", 0), "epipolar": report.get("epipolar"),
        "not_begun": report.get("not_begun", []), "matches": matches,
        "tracks": report.get("tracks", 0), "aligned": report["aligned"],
        "alignment_scale": report["alignment_scale"], "adjustment_seconds": report["seconds"],
        "phase_seconds": {k: round(v, 3) for k, v in report.get("phase_seconds", {}).items()},
        "statistics": model_statistics(report),
        "cpu_seconds": cpu,
        "seconds": seconds, "options": options.to_json()}


def not_begun(model, matched, options, left, matches=0, at="its input pose"):
    """The `refinement` section of a refinement that would begin nothing, or None. model: the
    model as written (colmap.model.Model), to be refined with its matches; matched: how many
    distinct observations (image, keypoint) those matches hold; left: what is left of
    options.max_seconds [s]; matches: how many refine_model would read (0: not known yet).
    Where what is left after reading them pays for neither the triangulation nor an adjustment
    alone (the constants above), the section is refine_model's own for a budget that pays for
    nothing (status out_of_time, every image kept at its pose: `at` says which), made without
    running it."""
    statistics = model.statistics()
    observations = statistics["observations"]
    left -= READING_SECONDS_PER_MATCH * matches
    if options.max_seconds <= 0 or options.retriangulations <= 0 or matched <= 0 or \
            left >= 2.0 * TRIANGULATION_SECONDS_PER_OBSERVATION * matched or \
            left >= ADJUSTMENT_ALONE_SECONDS_PER_OBSERVATION * observations:
        return None
    images = []
    for _, im in sorted(model.images.items()):
        seen = int(np.count_nonzero(np.asarray(im.point3D_ids) >= 0)) if im.point3D_ids is not None else 0
        images.append({"name": im.name, "refined": False, "kept": "the time budget was spent before it was refined",
                       "weak": False, "translation": 0.0, "rotation_deg": 0.0, "observations_input": seen,
                       "observations_refined": seen})
    error = statistics["reprojection_error"]
    report = {
        "status": "out_of_time", "refined": False,
        "message": "the time budget of %g s (%.3g s of it left) would not pay for refining a model of this size (%d "
                   "observations, %d in its matches; epipolar, triangulation, adjustment not begun): refine_model "
                   "not started, every image keeps %s" % (options.max_seconds, left, observations, matched, at),
        "images": images, "points_input": statistics["points"], "points_refined": statistics["points"],
        "observations_input": observations, "observations_refined": observations, "observations_filtered": 0,
        "reprojection_error_input": error, "reprojection_error_refined": error, "rounds": 0, "iterations": 0,
        "passes": 0, "retriangulations": 0, "not_begun": ["epipolar", "triangulation", "adjustment"],
        "aligned": False, "alignment_scale": 1.0, "seconds": 0.0}
    return section_of(report, 0, 0.0, 0.0, options)


def carried(model, poses):
    """The model with its images at `poses` ({image id: (qvec, tvec)}; an image without one as it
    is), each point moved with the first image of its track, as refine_model --start moves them
    (it stays where it was in that image's camera), and its reprojection error computed anew at
    the new poses (PINHOLE or SIMPLE_PINHOLE cameras). None where the points are not a
    colmap.model.PointTable (the live model's) or a camera is of another model."""
    table = model.points
    if not isinstance(table, colmap_model.PointTable):
        return None
    intrinsics = {}
    for cid, cam in model.cameras.items():
        if cam.model == "PINHOLE":
            intrinsics[cid] = tuple(cam.params[:4])
        elif cam.model == "SIMPLE_PINHOLE":
            intrinsics[cid] = (cam.params[0], cam.params[0], cam.params[1], cam.params[2])
        else:
            return None
    ids = np.array(sorted(model.images), np.int64)
    images = {}
    for iid in ids.tolist():
        im = model.images[iid]
        q, t = poses.get(iid, (im.qvec, im.tvec))
        images[iid] = colmap_model.Image(iid, q, t, im.camera_id, im.name, im.xys, im.point3D_ids)

    def frames(of):
        return (np.stack([geometry.rotation_of(of[i].qvec) for i in ids.tolist()]).reshape(-1, 3, 3),
                np.array([of[i].tvec for i in ids.tolist()], float).reshape(-1, 3))
    r_old, t_old = frames(model.images)
    r_new, t_new = frames(images)
    if len(table) == 0:
        return colmap_model.Model(dict(model.cameras), images, table)
    counts = np.diff(table.offsets)
    obs = np.searchsorted(ids, table.image_ids)
    if np.any(obs >= len(ids)) or np.any(ids[np.minimum(obs, len(ids) - 1)] != table.image_ids):
        return None  # a track names an image the model does not hold
    first = obs[table.offsets[:-1][counts > 0]]
    xyz = table.xyz.copy()
    has = counts > 0
    in_camera = np.einsum("nij,nj->ni", r_old[first], xyz[has]) + t_old[first]
    xyz[has] = np.einsum("nji,nj->ni", r_new[first], in_camera - t_new[first])
    owner = np.repeat(np.arange(len(table)), counts)
    p = np.einsum("nij,nj->ni", r_new[obs], xyz[owner]) + t_new[obs]
    k = np.array([intrinsics[images[i].camera_id] for i in ids.tolist()], float).reshape(-1, 4)[obs]
    sizes = np.array([len(images[i].xys) for i in ids.tolist()], np.int64)
    base = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    xys = np.concatenate([images[i].xys for i in ids.tolist()]) if sizes.sum() else np.zeros((0, 2))
    seen = xys[base[obs] + table.point2D_idxs]
    with np.errstate(divide="ignore", invalid="ignore"):
        projected = np.stack([k[:, 0] * p[:, 0] / p[:, 2] + k[:, 2], k[:, 1] * p[:, 1] / p[:, 2] + k[:, 3]], axis=1)
        error = np.linalg.norm(projected - seen, axis=1)
        mean = np.bincount(owner, error, len(table)) / np.maximum(counts, 1)
    mean = np.where(has & np.isfinite(mean), mean, -1.0)
    return colmap_model.Model(dict(model.cameras), images, colmap_model.PointTable(
        table.ids, xyz, table.rgb, mean, table.offsets, table.image_ids, table.point2D_idxs))


def model_statistics(report):
    """The refined model's statistics (colmap/model.py Model.statistics) from refine_model's
    report, as it counts them: reading the model back cost 1.5-1.7 s of a 30-minute session's
    finish."""
    registered, points, observations = len(report["images"]), report["points_refined"], report["observations_refined"]
    return {"registered": registered, "points": points, "observations": observations,
            "track_length": observations / points if points else 0.0,
            "obs_per_image": observations / registered if registered else 0.0,
            "reprojection_error": report["reprojection_error_refined"] if points else 0.0}


def keep_copy(model_path, unrefined):
    """A copy of the model folder in `unrefined`, written beside it and swapped in
    (durable.replace_folder): sparse/unrefined is never missing or half written (it was removed,
    then copied again)."""
    made = tempfile.mkdtemp(prefix=".unrefined_", dir=os.path.dirname(os.path.abspath(unrefined)))
    try:
        os.rmdir(made)
        shutil.copytree(model_path, made)
        durable.replace_folder(made, unrefined)
    finally:
        shutil.rmtree(made, ignore_errors=True)


def write_poses(model, poses, path):
    """The model folder `path` of `model`'s cameras and its images at `poses` ({image id: (qvec,
    tvec)}; an image without one: as it is), without 2D points or points: poses alone, as
    refine_model --start and --reference read them. Returns `path`."""
    out = colmap_model.Model(dict(model.cameras))
    empty, none = np.zeros((0, 2)), np.zeros(0, np.int64)
    for iid, im in model.images.items():
        q, t = poses.get(iid, (im.qvec, im.tvec))
        out.images[iid] = colmap_model.Image(iid, q, t, im.camera_id, im.name, empty, none)
    colmap_model.write_model(out, path, binary=True)
    return path


class ModelRefinement:
    """What colmap_bridge and colmap_from_selection do with the known-pose model: keep it as
    DIR/sparse/unrefined, refine it into DIR/sparse/0 (re-triangulating with the project's
    matches), and give the report's `refinement` section. Whatever fails, the unrefined model
    stays in DIR/sparse/0 and the section says why."""

    def __init__(self, options=None, tool=None, log=None, progress=None):
        """progress: called with each of refine_model's progress lines (a line a second), or None."""
        self.options = options or RefinementOptions()
        self.tool = tool
        self.log = log or (lambda level, text: None)
        self.progress = progress

    def apply(self, project, model_path, model=None, matched=0, start_poses=None):
        """Refines `model_path` (DIR/sparse/0) in place, keeping it as DIR/sparse/unrefined;
        returns the report's `refinement` section. model, matched: the model written there and
        the distinct observations of the project's matches, when the caller holds them (the
        live finish): a budget that would pay for nothing (not_begun) does not start
        refine_model. start_poses ({image id: (qvec, tvec)}; refinement/background.py): where
        the refinement starts, in place of the model's poses (its points carried along by their
        first image); corrections are still measured against, and the result aligned to, the
        model's poses (sparse/unrefined). Out of time, the model at the poses it started from
        stays."""
        from ..colmap.database import DatabaseError
        from ..colmap.project import ProjectError
        unrefined = os.path.join(os.path.dirname(model_path), "unrefined")
        start = time.monotonic()
        try:
            keep_copy(model_path, unrefined)
            options, started, section = self.options, None, None
            if start_poses:
                # Their epipolar stage is done: the finish's own from there moved the median Sampson
                # distance 0.26 -> 0.20 px in 1.3 s of its 5 (the 1-minute walk); without it the
                # adjustment had that time too: 6.5 mm against 33 (the 10-minute walk, offline).
                options = copy.copy(options)
                options.epipolar = False
                if model is not None:
                    section = self._made_at_start(model_path, model, matched, start_poses, options, start)
            if start_poses and section is None:
                folder = tempfile.mkdtemp(prefix=".start_", dir=os.path.dirname(os.path.abspath(model_path)))
                started = write_poses(model if model is not None else colmap_model.read_model(model_path),
                                      start_poses, os.path.join(folder, "start"))
                # refine_model runs whatever the budget: out of time, its output is the model at
                # the start poses (not_begun's shortcut would leave the node's).
                model = None
            try:
                if section is None:
                    section = refine(model_path, model_path, options, database=project.database, tool=self.tool,
                                     log_path=project.log_path, deadline=project.deadline,
                                     log=lambda text: self.log("info", text), progress=self.progress,
                                     budget_start=start, model=model, matched=matched, start_model=started,
                                     max_matches=STRONGEST_MATCHES if started else 0)
            finally:
                if started:
                    shutil.rmtree(os.path.dirname(started), ignore_errors=True)
            if start_poses:
                section["started_from"] = "the poses refined while the recording went on (%d keyframes)" \
                    % len(start_poses)
        except (RefinementError, ProjectError, DatabaseError, colmap_model.ModelError, OSError, KeyError,
                ValueError) as e:
            message = "refinement failed, the unrefined model stays in %s: %s" % (model_path, e)
            self.log("error", message)
            return {"refined": False, "status": "error", "error": message, "unrefined_path": unrefined,
                    "seconds": time.monotonic() - start, "options": self.options.to_json()}
        section["unrefined_path"] = unrefined
        if section["status"] == "out_of_time" and not section["refined"]:
            # Every keyframe kept its pose for want of time (a long session's finish): said once,
            # with what would refine it, instead of a keyframe's "kept" below.
            self.log("warn", "refinement: not refined within its budget of %g s (%s); the model is at the given "
                             "poses. A longer budget refines it (colmap_bridge's ~refine_max_seconds, "
                             "colmap_from_selection's --refine-max-seconds)" % (self.options.max_seconds,
                                                                                 section["message"]))
        elif section["keyframes_kept"]:
            self.log("warn", "refinement: %d keyframes kept their input pose (%s: %s)" % (
                len(section["keyframes_kept"]), section["keyframes_kept"][0]["name"],
                section["keyframes_kept"][0]["why"]))
        return section

    def _made_at_start(self, model_path, model, matched, start_poses, options, start):
        """The finish from `start_poses` on a `model` its budget pays nothing for from there (a
        30-minute session's): the model at those poses made here (carried) and written to
        `model_path`, and not_begun's section with the corrections against the given poses. None
        where the budget pays for something or carried cannot make the model: refine_model
        --start runs then (at 30 minutes it read, set up and wrote for 4-5 s to give the same)."""
        at_start = carried(model, start_poses)
        if at_start is None:
            return None
        section = not_begun(at_start, matched, options, options.max_seconds - (time.monotonic() - start),
                            at="the pose it started from")
        if section is None:
            return None
        made = tempfile.mkdtemp(prefix=".start_", dir=os.path.dirname(os.path.abspath(model_path)))
        try:
            colmap_model.write_model(at_start, made, binary=True)
            durable.replace_folder(made, model_path)
        finally:
            shutil.rmtree(made, ignore_errors=True)
        self.log("info", "refinement: %s" % section["message"])
        moved = corrections(model, at_start)  # against the given poses, as refine_model's
        for k in section["keyframes"]:
            k["translation"], k["rotation_deg"] = moved.get(k["name"], (0.0, 0.0))
        section["seconds"] = time.monotonic() - start
        return section
