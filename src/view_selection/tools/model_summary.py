"""What a COLMAP project made by colmap_bridge or colmap_from_selection holds, in a few lines, and
the model drawn from above (PROJECT/model.png).

Reads the project folder as the tools leave it: PROJECT/sparse/0 (the model), PROJECT/database.db
(the matches) and PROJECT/report.json (how it was made). Prints the keyframes in the model of
those given, its 3D points and mean reprojection error, the pairs matched by path (guided by the
poses, or COLMAP's matcher where the poses disagreed with the images), what was skipped and why,
and the refinement's corrections. The figures of the model are read from sparse/0 itself, the
rest from the report. scripts/demo prints this after its run.

A folder that is not such a project, a model without 3D points or a missing report.json is an
error (exit 1) and nothing is written.

  rosrun view_selection model_summary ~/recording/colmap
  rosrun view_selection model_summary demo_output/model --no-picture
"""
import argparse
import json
import os
import sqlite3
import sys

from ..colmap.database import Database, DatabaseError
from ..colmap.model import ModelError, read_model

SHOWN = 5  # skipped items and kept keyframes named one by one; the rest are counted


class SummaryError(Exception):
    """A folder this tool cannot summarise; the message says why."""


def parse_args(argv):
    p = argparse.ArgumentParser(prog="model_summary", description=__doc__.split("\n")[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("project", help="a colmap_bridge ~project or colmap_from_selection --out folder")
    p.add_argument("--picture", help="where the model from above is drawn (default PROJECT/model.png)")
    p.add_argument("--no-picture", action="store_true", help="print only, draw nothing")
    return p.parse_args(argv)


class Project:
    """The three parts of a project folder, read and checked; SummaryError names what is wrong."""

    def __init__(self, folder):
        self.root = os.path.abspath(folder)
        if not os.path.isdir(self.root):
            raise SummaryError("no folder at %s" % self.root)
        self.model_path = os.path.join(self.root, "sparse", "0")
        self.database = os.path.join(self.root, "database.db")
        has_model, has_database = os.path.isdir(self.model_path), os.path.isfile(self.database)
        if not has_model and not has_database:
            raise SummaryError("%s is not a COLMAP project: it has neither database.db nor sparse/0 (give the "
                               "folder colmap_bridge's ~project or colmap_from_selection's --out names)" % self.root)
        if not has_database:
            raise SummaryError("%s has no database.db: not a project of colmap_bridge or colmap_from_selection"
                               % self.root)
        report = os.path.join(self.root, "report.json")
        if not os.path.isfile(report):
            raise SummaryError("%s has no report.json: its model was not finished (colmap_bridge writes it at the "
                               "end of a recording or on ~finish, colmap_from_selection when it is done)" % self.root)
        try:
            with open(report) as f:
                self.report = json.load(f)
        except (OSError, ValueError) as e:
            raise SummaryError("cannot read %s: %s" % (report, e))
        if not isinstance(self.report, dict):
            raise SummaryError("%s is not a report of colmap_bridge or colmap_from_selection" % report)
        if not has_model:
            raise SummaryError("%s has no model (sparse/0)%s" % (self.root, self._why()))
        try:
            self.model = read_model(self.model_path)
        except (ModelError, OSError, ValueError) as e:
            raise SummaryError("cannot read the model in %s: %s" % (self.model_path, e))
        if not self.model.points:
            raise SummaryError("the model in %s has %d keyframes and no 3D points%s" % (
                self.model_path, len(self.model.images), self._why()))
        try:
            with Database(self.database) as d:
                self.counts = d.counts()
        except (DatabaseError, sqlite3.Error) as e:
            raise SummaryError("cannot read %s: %s" % (self.database, e))

    def _why(self):
        error = self.report.get("model_error") or (self.report.get("errors") or [{}])[-1].get("error")
        return " (report.json: %s)" % error if error else ""


def _named(items, text):
    """'a: why; b: why; and 3 more' for the first SHOWN items."""
    shown = "; ".join(text(i) for i in items[:SHOWN])
    return shown + ("; and %d more" % (len(items) - SHOWN) if len(items) > SHOWN else "")


def summary_lines(project):
    """The summary, a list of lines."""
    r, model = project.report, project.model
    stats = model.statistics()
    lines = []
    kind = r.get("model", "known_poses")
    refinement = r.get("refinement") or {}
    how = {"known_poses": "the keyframes at their given poses", "mapper": "COLMAP's mapper"}.get(kind, kind)
    if refinement.get("refined"):
        how += ", refined"
    lines.append("model       %s (%s)" % (project.model_path, how))
    given = r.get("keyframes")
    seeing = sum(1 for im in model.images.values() if (im.point3D_ids >= 0).any())
    lines.append("keyframes   %d%s in the model (%d see its points), %d 3D points, mean reprojection error %.2f px, "
                 "mean track length %.1f" % (stats["registered"], " of %d" % given if given is not None else "",
                                             seeing, stats["points"], stats["reprojection_error"],
                                             stats["track_length"]))
    m = r.get("matching") or {}
    paths = ("%d guided by the poses, %d by the images' geometry, %d by COLMAP's matcher, %d with too few matches "
             "for it" % (m.get("guided", 0), m.get("images", 0), m.get("fallback", 0), m.get("unmatched", 0))
             if m else "all by COLMAP's matcher")
    wanted = r.get("final_pairs", 0) + r.get("continuity_pairs", 0)
    lines.append("pairs       %d matched%s (%s), %d verified in the database, %d wasted (matched, not wanted at "
                 "the end)" % (project.counts["pairs_with_geometry"], " of %d wanted" % wanted if wanted else "", paths,
                               project.counts["pairs_verified"], r.get("pairs_wasted", 0)))
    if m.get("band_px"):
        lines.append("            guided search band median %.1f px, 90th percentile %.1f px"
                     % (m["band_px"]["median"], m["band_px"]["p90"]))
    if "ate_rmse" in r:
        lines.append("            ATE %.4f against the selection's poses (%d images)" % (r["ate_rmse"],
                                                                                       r.get("ate_images", 0)))
    skipped = r.get("skipped") or {}
    images, pairs = skipped.get("images") or [], skipped.get("pairs") or []
    missing = r.get("images_missing") or []
    featureless = sorted(set(r.get("images_with_no_features") or []) - {s["item"] for s in images})
    if not (images or pairs or missing or featureless):
        lines.append("skipped     nothing")
    if images:
        lines.append("skipped     %d image%s: %s" % (len(images), "s" if len(images) != 1 else "",
                                                     _named(images, lambda s: "%s (%s)" % (s["item"], s["error"]))))
    if pairs:
        lines.append("%s%d pair%s: %s" % ("skipped     " if not images else " " * 12, len(pairs),
                                          "s" if len(pairs) != 1 else "",
                                          _named(pairs, lambda s: "%s (%s)" % (s["item"], s["error"]))))
    if missing:
        lines.append("            %d keyframe%s without an image in the project: %s" % (
            len(missing), "s" if len(missing) != 1 else "", _named(missing, str)))
    if featureless:
        lines.append("            %d image%s without features (blank?), in the model without points: %s" % (
            len(featureless), "s" if len(featureless) != 1 else "", _named(featureless, str)))
    if refinement.get("refined"):
        kept = refinement.get("keyframes_kept") or []
        lines.append("refinement  %s: %d keyframes moved, median %.3g and max %.3g (the poses' units), turned median "
                     "%.2g and max %.2g deg; reprojection error %.2f -> %.2f px" % (
                         refinement.get("status"), refinement.get("keyframes_refined", 0),
                         refinement.get("translation_median", 0.0), refinement.get("translation_max", 0.0),
                         refinement.get("rotation_median_deg", 0.0), refinement.get("rotation_max_deg", 0.0),
                         *(refinement.get("reprojection_error") or [0.0, 0.0])))
        if kept:
            lines.append("            %d kept their given pose: %s" % (
                len(kept), _named(kept, lambda k: "%s (%s)" % (k["name"], k["why"]))))
    elif refinement:
        lines.append("refinement  none: %s" % (refinement.get("error") or refinement.get("message") or
                                               refinement.get("status")))
    elif kind == "known_poses":
        lines.append("refinement  off: the keyframes are at their given poses")
    if r.get("model_error"):
        lines.append("error       %s" % r["model_error"])
    return lines


def draw_picture(project, path):
    """The model from above into `path`, written whole or not at all."""
    from ..colmap.top_view import draw
    stats = project.model.statistics()
    tmp = path + ".tmp.png"
    try:
        draw(project.model, tmp, "%s: %d keyframes, %d points" % (os.path.basename(project.root) or project.root,
                                                                  stats["registered"], stats["points"]))
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        project = Project(args.project)
        lines = summary_lines(project)
        if not args.no_picture:
            picture = os.path.abspath(args.picture or os.path.join(project.root, "model.png"))
            lines.append("picture     %s (the model from above)" % draw_picture(project, picture))
        lines.append("open it     colmap gui --database_path %s --image_path %s --import_path %s" % (
            project.database, os.path.join(project.root, "images"), project.model_path))
    except SummaryError as e:
        print("model_summary: error: %s" % e, file=sys.stderr)
        return 1
    except OSError as e:
        print("model_summary: error: cannot draw the picture: %s" % e, file=sys.stderr)
        return 1
    print("\n".join(lines), flush=True)
    return 0
