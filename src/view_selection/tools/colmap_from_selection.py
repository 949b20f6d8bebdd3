"""From a view selection to a sparse COLMAP model, in one command.

Takes a folder written by the node's ~export or by select_views (selection.json and pairs.txt)
and runs COLMAP 3.8 (CPU) on exactly the selected pairs:

  1. feature_extractor on the keyframe images only, a PINHOLE camera with the known intrinsics
     from selection.json;
  2. matches_importer with pairs.txt (--match_type pairs): only the selected pairs are matched;
  3. mapper, started from the selection's initial pair (s, C_s[0]) when --init-pair is on;
  4. the model's statistics: registered images, points, track length, reprojection error.

With --model known_poses it builds instead the model a user with SLAM poses asks for, exactly
as colmap_bridge does online (the same code): the project laid out as the bridge keeps it
(OUT/images with the keyframe images, linked where the file system allows, OUT/database.db,
OUT/sparse/0, OUT/report.json), the keyframes at their selection.json poses and 3D points from
point_triangulator with the cameras held fixed, then refined (issue 29: poses and points
bundle-adjusted with the intrinsics fixed, outliers filtered, points re-triangulated at the
refined poses, the model as triangulated kept in OUT/sparse/unrefined; --refine off keeps the
keyframes at their given poses). On the same frames, offline and online give the same model.

The images are found through selection.json's params: "image_path" relative to the export
folder (the node with ~save_keyframe_images writes them there), or to params "dataset" (a
select_views folder). --image-path overrides both. Output: OUT/database.db, OUT/sparse/0/,
OUT/report.json.

  rosrun view_selection colmap_from_selection /tmp/my_selection
  rosrun view_selection colmap_from_selection /tmp/my_selection --out /tmp/my_model --threads 2

Every selected pair is matched (and, with known_poses, each keyframe with the one before it). Exit
status: 0 when the model has them all (a pair that COLMAP's verification refused counts: it was
matched), 1 on an error, 3 when a wanted pair was never matched (an image missing or without
features, a COLMAP run that kept failing): report.json's pairs_lost names each with its reason.
"""
import argparse
import os
import shutil
import sqlite3
import sys
import time

from ..allocator import pad_heap
from ..colmap.database import DatabaseError
from ..colmap.project import ColmapProject, ProjectError, write_json_atomically
from ..export_folder import ExportError, ExportFolder
from ..live.work import LiveWork
from ..refinement.refiner import ModelRefinement, RefinementOptions
from ..matching.backend import PoseGuidedBackend
from ..matching.loops import LoopOptions
from ..progress import Progress


def log(msg):
    print("[colmap_from_selection %s] %s" % (time.strftime("%H:%M:%S"), msg), file=sys.stderr, flush=True)


def parse_args(argv):
    p = argparse.ArgumentParser(prog="colmap_from_selection", description=__doc__.split("\n")[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("export", help="folder with selection.json and pairs.txt (~export or select_views --out)")
    p.add_argument("--out", help="output folder (default EXPORT/colmap)")
    p.add_argument("--image-path", help="folder the image names are relative to (default: from selection.json)")
    p.add_argument("--init-pair", choices=["on", "off"], default="off",
                   help="start the mapper from the selection's initial pair (default off: measured "
                        "no better than COLMAP's own choice, docs/results.md)")
    p.add_argument("--threads", type=int, default=-1, help="COLMAP threads (default -1: all cores)")
    p.add_argument("--seed", type=int, default=0, help="mapper random seed (default 0)")
    p.add_argument("--colmap", default="colmap", help="the colmap executable")
    p.add_argument("--model", choices=["mapper", "known_poses"], default="mapper",
                   help="mapper (default): COLMAP's mapper from scratch; known_poses: the keyframes at "
                        "their poses, points from point_triangulator (colmap_bridge's model)")
    p.add_argument("--matcher", choices=["guided", "colmap"],
                   help="guided (default with known_poses): OpenCV SIFT and matches guided by the selection's "
                        "poses, COLMAP's matcher for pairs whose poses disagree with the images (colmap_bridge's "
                        "~matcher); colmap (default with mapper): COLMAP's feature_extractor and matches_importer")
    p.add_argument("--triangulation", choices=["live", "colmap"], default="live",
                   help="known_poses: live (default; colmap_bridge's ~triangulation): the points triangulated and "
                        "filtered by the package, as the bridge does while pairs verify; colmap: COLMAP's "
                        "point_triangulator over the whole model")
    p.add_argument("--refine", choices=["on", "off"], default="on",
                   help="known_poses: refine the model (default on, as colmap_bridge's ~refine): poses and points "
                        "bundle-adjusted, the SLAM poses' drift corrected; off: the keyframes stay at their poses")
    p.add_argument("--refine-retriangulations", type=int, default=RefinementOptions().retriangulations,
                   help="known_poses: re-triangulations at the refined poses (default %(default)s)")
    p.add_argument("--refine-max-seconds", type=float, default=0.0,
                   help="known_poses: the refinement's time budget [s]; once spent, the model is what the adjustment "
                        "reached (colmap_bridge's ~refine_max_seconds; default 0: no limit)")
    p.add_argument("--refine-tool", help="the refine_model executable (default: found beside this tool)")
    p.add_argument("--no-continuity", action="store_true",
                   help="known_poses: match only the selection's pairs, not also each keyframe with the "
                        "one before it (colmap_bridge's ~continuity_pairs)")
    p.add_argument("--no-loop-pairs", action="store_true",
                   help="known_poses: do not also match pairs across revisits that the poses do not show "
                        "(colmap_bridge's ~loop_pairs; matching/loops.py: what lets the refinement see drift)")
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    # Long work says how far it is on stderr: extraction and matching by their counts, the
    # refinement by refine_model's own lines (docstring of view_selection.progress).
    progress = Progress()

    def say(level, text):
        progress.clear()
        log(text)
    try:
        export = ExportFolder(args.export)
        if len(export.keyframes) < 2:
            raise ExportError("the selection has %d keyframes; a model needs at least 2" % len(export.keyframes))
        images = export.image_root(args.image_path)
        out = os.path.abspath(args.out or os.path.join(export.folder, "colmap"))
        if os.path.exists(out):
            shutil.rmtree(out)
        project = ColmapProject(out, args.colmap, args.threads)
        os.makedirs(project.images)
        project.link_images(export.keyframes, images)
        project.open()
        if args.threads > 0:
            import cv2
            cv2.setNumThreads(args.threads)
        pad_heap()  # SIFT beside the features held (allocator.py)
        known = args.model == "known_poses"
        matcher = args.matcher or ("guided" if known else "colmap")
        backend = PoseGuidedBackend(project, progress=progress.report) if matcher == "guided" else None
        refinement = None
        if known and args.refine == "on":
            refinement = ModelRefinement(RefinementOptions(retriangulations=args.refine_retriangulations,
                                                           max_seconds=args.refine_max_seconds,
                                                           timeout=3600.0,  # offline: a large model may take long
                                                           threads=args.threads),
                                         tool=args.refine_tool, log=say,
                                         progress=lambda line: progress.note("refining: " + line))
        work = LiveWork(project, continuity=known and not args.no_continuity,
                        loops=LoopOptions() if known and not args.no_loop_pairs else None,
                        log=say, backend=backend,
                        triangulation=args.triangulation if known else "colmap", refinement=refinement)
        log("%s model of %d keyframes, %d pairs" % ("known-pose" if known else "mapper", len(export.keyframes),
                                                    len(export.pairs)))
        if not known:
            project.init_pair = export.initial_pair() if args.init_pair == "on" else None
        report = work.build_model(export.keyframes, export.pairs, args.model, seed=args.seed)
        progress.end()
        report.update({"export": export.folder, "images": images, "seconds": project.seconds,
                       "init_pair": args.init_pair, "matcher": matcher})
        stages = work.clock.summary()
        if backend:
            report["matching"] = backend.path_counts()
            stages.update(backend.clock.summary())
        report["stages"] = stages
        write_json_atomically(os.path.join(out, "report.json"), report)
        lost = report.get("pairs_lost", [])
        print("colmap_from_selection: %d of %d keyframes %s, %d points, reprojection error %.3f px in %s (%d of %d "
              "pairs verified, %d not verified, %d lost); %s"
              % (report.get("registered", 0), len(export.keyframes), "at their poses" if known else "registered",
                 report.get("points", 0), report.get("reprojection_error", 0.0), report["model_path"],
                 report["pairs_verified"], report.get("pairs_wanted", len(export.pairs)),
                 report.get("pairs_not_verified", 0), len(lost), os.path.join(out, "report.json")))
        if lost:
            # A wanted pair that never got matched (not one that COLMAP's verification refused)
            # is a model missing what was asked for: not a success.
            print("colmap_from_selection: error: %d wanted pairs are not in the model, e.g. %s (%s); report.json "
                  "lists them (pairs_lost)" % (len(lost), lost[0]["pair"], lost[0]["reason"]), file=sys.stderr)
            return 3
        return 0
    except (ExportError, ProjectError, DatabaseError, sqlite3.Error, OSError) as e:
        progress.clear()
        print("colmap_from_selection: error: %s" % e, file=sys.stderr)
        return 1
