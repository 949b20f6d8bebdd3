"""The known-pose model refined: refine_model (C++/Ceres) run as a process on a COLMAP model
folder, as the project runs COLMAP (a timeout, a clear error naming the stage, killed with its
parent), then the points re-triangulated at the refined poses and refined again.

  1. refine_model on the model triangulated at the SLAM poses: poses and points adjusted with
     the intrinsics fixed, a robust (Cauchy) loss, observations beyond 4 px filtered, round after
     round; implausible corrections kept at the SLAM pose;
  2. re-triangulation at the refined poses (point_triangulator, points cleared): matches that
     the drifted poses rejected become points now;
  3. refine_model again, its corrections measured against the SLAM poses.

Points triangulated at wrong poses are outlier observations at the right ones: an adjustment
without filtering and re-triangulation follows them (issue 29: COLMAP's bundle_adjuster made a
drifted DTU set 7.3x worse). The seam: `refine(model folder, which images stay fixed) -> the
refined folder + the report's section`, with the per-keyframe corrections.
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from .. import geometry
from ..colmap import model as colmap_model
from ..colmap.process import Colmap, ColmapError, _death_signal_prefix


class RefinementError(Exception):
    """The refinement could not run (tool missing, failed, timed out); the unrefined model stays."""


class RefinementOptions:
    """What refine_model is given (its --help says more) and how the steps run.

    retriangulations: how many times the points are re-triangulated at the refined poses and
    refined again (0: one adjustment on the model as it came)."""

    def __init__(self, loss="cauchy", loss_scale=1.0, max_error=4.0, min_angle=1.5, rounds=4, iterations=100,
                 min_observations=15, max_correction_depth_ratio=0.5, max_correction_deg=15.0,
                 retriangulations=1, threads=-1, timeout=120.0):
        self.loss, self.loss_scale, self.max_error, self.min_angle = loss, float(loss_scale), float(max_error), float(min_angle)
        self.rounds, self.iterations, self.min_observations = int(rounds), int(iterations), int(min_observations)
        self.max_correction_depth_ratio, self.max_correction_deg = float(max_correction_depth_ratio), float(max_correction_deg)
        self.retriangulations, self.threads, self.timeout = int(retriangulations), int(threads), float(timeout)

    def arguments(self):
        return ["--loss", self.loss, "--loss-scale", repr(self.loss_scale), "--max-error", repr(self.max_error),
                "--min-angle", repr(self.min_angle), "--rounds", str(self.rounds), "--iterations", str(self.iterations),
                "--min-observations", str(self.min_observations),
                "--max-correction-depth-ratio", repr(self.max_correction_depth_ratio),
                "--max-correction-deg", repr(self.max_correction_deg),
                "--threads", str(max(0, self.threads))]

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


def run_refine_model(tool, model, output, report, options, fixed=(), reference=None, log_path=None, timeout=None):
    """One refine_model process; returns its report (dict). RefinementError when it cannot run,
    fails or exceeds the timeout (then it is killed)."""
    args = [tool, "--input", model, "--output", output, "--report", report, "--quiet"] + options.arguments()
    if reference:
        args += ["--reference", reference]
    if fixed:
        listing = output.rstrip("/") + ".fixed.txt"
        with open(listing, "w") as f:
            f.write("".join(n + "\n" for n in fixed))
        args += ["--fixed", listing]
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
    try:
        with open(report) as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        raise RefinementError("refine_model wrote no readable report (%s)" % e)


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


def refine(model_dir, output, options=None, fixed=(), retriangulate=None, tool=None, log_path=None, deadline=None,
           log=None):
    """Refines the model in `model_dir` into `output` (replaced only at the end; on any error
    `output` is untouched and RefinementError says why). `fixed`: image names that must not
    move. `retriangulate(given, made)`: writes into `made` the points triangulated at the poses
    of the poses-only model `given` (None: no re-triangulation). `deadline`: time.monotonic()
    by which it must be done. Returns the report's `refinement` section (dict)."""
    options = options or RefinementOptions()
    log = log or (lambda text: None)
    tool = find_refine_tool(tool)
    start = time.monotonic()
    parent = os.path.dirname(os.path.abspath(output))
    os.makedirs(parent, exist_ok=True)
    work = tempfile.mkdtemp(prefix=".refine_", dir=parent)
    stages = []

    def time_left():
        if deadline is None:
            return options.timeout
        left = deadline - time.monotonic()
        if left <= 1.0:
            raise RefinementError("no time left for the refinement")
        return min(options.timeout, left)

    try:
        current = os.path.abspath(model_dir)
        reports = []
        for stage in range(options.retriangulations + 1):
            if stage > 0:
                if retriangulate is None:
                    break
                given, made = os.path.join(work, "given%d" % stage), os.path.join(work, "triangulated%d" % stage)
                colmap_model.write_model(poses_only(colmap_model.read_model(current)), given, binary=False)
                t0 = time.monotonic()
                retriangulate(given, made)
                stages.append({"stage": "retriangulation", "seconds": time.monotonic() - t0})
                current = made
            made = os.path.join(work, "refined%d" % stage)
            t0 = time.monotonic()
            report = run_refine_model(tool, current, made, made + ".json", options, fixed,
                                      reference=model_dir if stage > 0 else None, log_path=log_path,
                                      timeout=time_left())
            stages.append({"stage": "adjustment", "seconds": time.monotonic() - t0, "status": report["status"],
                           "rounds": report["rounds"], "iterations": report["iterations"],
                           "points": [report["points_input"], report["points_refined"]],
                           "reprojection_error": [report["reprojection_error_input"],
                                                  report["reprojection_error_refined"]]})
            reports.append(report)
            log("refinement stage %d: %s" % (stage + 1, report["message"]))
            current = made
            if not report["refined"]:
                break  # diverged or nothing to refine: the input stands
        first, last = reports[0], reports[-1]
        refined = any(r["refined"] for r in reports)
        final = current if last["refined"] or len(reports) == 1 else os.path.join(work, "refined%d" % (len(reports) - 2))
        if not last["refined"] and len(reports) > 1:
            last = reports[-2]  # a later stage that could not refine leaves the earlier result
        from ..colmap.project import replace_folder
        replace_folder(final, os.path.abspath(output))
        keyframes = []
        for im in last["images"]:
            keyframes.append({"name": im["name"], "refined": im["refined"], "kept": im["kept"] or None,
                              "translation": im["translation"], "rotation_deg": im["rotation_deg"],
                              "observations": [im["observations_input"], im["observations_refined"]]})
        moved = [k for k in keyframes if k["refined"]]
        translations = sorted(k["translation"] for k in moved)
        rotations = sorted(k["rotation_deg"] for k in moved)
        return {
            "status": last["status"] if refined else reports[-1]["status"], "refined": refined,
            "message": last["message"] if refined else reports[-1]["message"],
            "keyframes": keyframes, "keyframes_refined": len(moved),
            "keyframes_kept": [{"name": k["name"], "why": k["kept"]} for k in keyframes if k["kept"]],
            "translation_median": translations[len(translations) // 2] if translations else 0.0,
            "translation_max": translations[-1] if translations else 0.0,
            "rotation_median_deg": rotations[len(rotations) // 2] if rotations else 0.0,
            "rotation_max_deg": rotations[-1] if rotations else 0.0,
            "points": [first["points_input"], last["points_refined"]],
            "observations": [first["observations_input"], last["observations_refined"]],
            "reprojection_error": [first["reprojection_error_input"], last["reprojection_error_refined"]],
            "aligned": last["aligned"], "alignment_scale": last["alignment_scale"],
            "retriangulations": sum(1 for s in stages if s["stage"] == "retriangulation"),
            "stages": stages, "seconds": time.monotonic() - start, "options": options.to_json()}
    finally:
        shutil.rmtree(work, ignore_errors=True)


class ModelRefinement:
    """What colmap_bridge and colmap_from_selection do with the known-pose model: keep it as
    DIR/sparse/unrefined, refine it into DIR/sparse/0 (re-triangulating with the project's
    matches), and give the report's `refinement` section. Whatever fails, the unrefined model
    stays in DIR/sparse/0 and the section says why."""

    def __init__(self, options=None, tool=None, log=None):
        self.options = options or RefinementOptions()
        self.tool = tool
        self.log = log or (lambda level, text: None)

    def apply(self, project, model_path):
        from ..colmap.project import ProjectError
        unrefined = os.path.join(os.path.dirname(model_path), "unrefined")
        start = time.monotonic()
        try:
            if os.path.exists(unrefined):
                shutil.rmtree(unrefined)
            shutil.copytree(model_path, unrefined)
            section = refine(model_path, model_path, self.options, retriangulate=project.triangulate, tool=self.tool,
                             log_path=project.log_path, deadline=project.deadline,
                             log=lambda text: self.log("info", text))
        except (RefinementError, ProjectError, colmap_model.ModelError, OSError, KeyError, ValueError) as e:
            message = "refinement failed, the unrefined model stays in %s: %s" % (model_path, e)
            self.log("error", message)
            return {"refined": False, "status": "error", "error": message, "unrefined_path": unrefined,
                    "seconds": time.monotonic() - start, "options": self.options.to_json()}
        section["unrefined_path"] = unrefined
        if section["keyframes_kept"]:
            self.log("warn", "refinement: %d keyframes kept their input pose (%s: %s)" % (
                len(section["keyframes_kept"]), section["keyframes_kept"][0]["name"],
                section["keyframes_kept"][0]["why"]))
        return section
