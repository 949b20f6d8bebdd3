"""Geometry of the pairs each strategy matched in an evaluate_colmap run, from ground truth.

For each strategy: number of pairs, how many COLMAP verified, and the median baseline (distance
between camera centres, ground-truth units) and angle between optical axes, over all pairs, the
verified ones (with their median inlier count) and the failed ones. Shows whether a selection asks
for pairs too wide for SIFT matching.

  rosrun view_selection pair_geometry RUN_DIR [SETTING] STRATEGY...
  rosrun view_selection pair_geometry /tmp/eval-kitchen50 default exhaustive nearest ours-paper
"""
import math
import os
import statistics
import sys

from ..colmap.database import Database
from ..evaluation.tum import read_list, read_trajectory
from ..geometry import rotation_of


def poses_by_name(run):
    """{image name: (centre, optical axis)} through the run's rgb.txt and groundtruth.txt."""
    truth = {stamp: (centre, rotation_of(q)[:, 2]) for stamp, centre, q in
             read_trajectory(os.path.join(run, "data", "groundtruth.txt"))}
    stamps = sorted(truth)
    pose = {}
    for row in read_list(os.path.join(run, "data", "rgb.txt")):
        nearest = min(stamps, key=lambda s: abs(s - float(row[0])))
        pose[os.path.basename(row[1])] = truth[nearest]
    return pose


def median(values):
    return statistics.median(values) if values else float("nan")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 2 or argv[0] in ("-h", "--help"):
        print("usage: " + __doc__)
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    run, rest = argv[0], argv[1:]
    setting = "default"
    if rest and rest[0] in ("default", "relaxed"):
        setting, rest = rest[0], rest[1:]
    pose = poses_by_name(run)

    def geometry(a, b):
        (pa, za), (pb, zb) = pose[a], pose[b]
        dot = max(-1.0, min(1.0, float(sum(x * y for x, y in zip(za, zb)))))
        return math.dist(pa, pb), math.degrees(math.acos(dot))

    for strategy in rest:
        with Database(os.path.join(run, setting, strategy, "database.db")) as d:
            ids = d.image_ids()
            inliers = d.inlier_counts()
            pairs = [(a, b, inliers.get(tuple(sorted((ids[a], ids[b]))), 0)) for a, b in d.matched_names()]
        ok = [(geometry(a, b), n) for a, b, n in pairs if n > 0]
        bad = [geometry(a, b) for a, b, n in pairs if n == 0]
        every = [g for g, _ in ok] + bad
        print("%-15s %4d pairs, %4d verified | all: baseline %.2f, angle %.1f deg | verified: baseline %.2f, "
              "angle %.1f deg, inliers %d | failed: baseline %.2f, angle %.1f deg" % (
                  strategy, len(pairs), len(ok), median([g[0] for g in every]), median([g[1] for g in every]),
                  median([g[0] for g, _ in ok]), median([g[1] for g, _ in ok]), median([n for _, n in ok]) if ok else 0,
                  median([g[0] for g in bad]), median([g[1] for g in bad])))
    return 0
