"""Cheap what-if for select_views settings, on an evaluate_colmap output folder.

The exhaustive run of evaluate_colmap matched and verified every pair, so the result of matching
any subset of pairs is already in its database. For each variant (a label and select_views
arguments) this script runs select_views on the same frames, keeps only the selected pairs'
matches and two-view geometries in a copy of the exhaustive database, runs `colmap mapper`
(--repeats times, run k with --random_seed k: the mapper's RANSAC and initial pair search
vary with the seed; with one thread a seed gives the same model every time), and reports verified pairs, registered
images, reprojection error and ATE, as the median and the min-max over the runs. No matching is
redone, so a variant costs mapping runs (seconds to a minute each) instead of a matching run.

A variant is LABEL:SPEC where SPEC is one of
  select_views arguments         e.g. "ratio0.5:--completion reachable --min-covisible-ratio 0.5"
  @PAIRS_FILE                    a ready pairs.txt (another tool's, or written by hand)
  =STRATEGY                      the pairs that STRATEGY matched in this run (its database),
                                 e.g. "exhaustive:=exhaustive", "sequential:=sequential"
  %sequential N                  each image with the next N in capture order (rgb.txt order;
                                 COLMAP's sequential_matcher uses name order, which differs on
                                 some sets)
Variants can also come from --variants-file (one LABEL:SPEC a line, # comments).

  rosrun view_selection sweep_selection --run /tmp/eval-kitchen50 --setting default --repeats 3 --threads 1 \\
      --tools BUILD/devel/lib/view_selection \\
      --variant "paper:--completion paper" --variant "exhaustive:=exhaustive"

Output: RUN/sweep-SETTING (or --out): one folder per variant, sweep.json and sweep.md (a table of
medians and min-max). An existing sweep.json in the output folder is extended: variants already
there with the same label are replaced.

Matching time is not measured here (it scales with the number of pairs; see evaluate_colmap).
"""

import argparse
import json
import os
import shutil
import subprocess
import sys

from ..colmap.database import Database
from ..evaluation.mapping import map_once, spread
from ..evaluation.tum import read_list

METRICS = ("registered", "reprojection_error", "ate_rmse", "points")


def capture_order(data):
    return [os.path.basename(row[1]) for row in read_list(os.path.join(data, "rgb.txt"))]


def fmt(stat, digits, images=None):
    if stat is None:
        return "-"
    f = (lambda v: "%d" % v) if digits == 0 else (lambda v: ("%." + str(digits) + "g") % v)
    text = f(stat["median"])
    if images is not None:
        text += "/%d" % images
    if stat["n"] > 1 and stat["min"] != stat["max"]:
        text += " [%s-%s]" % (f(stat["min"]), f(stat["max"]))
    return text


def markdown(results, units):
    lines = ["| variant | pairs | verified | registered | reproj. [px] | ATE [%s] | 3D points | runs |" % units,
             "|---|---|---|---|---|---|---|---|"]
    for r in results:
        s = r.get("summary", {})
        lines.append("| %s | %d | %d | %s | %s | %s | %s | %d |" % (
            r["label"], r["pairs"], r["verified"], fmt(s.get("registered"), 0, r["images"]),
            fmt(s.get("reprojection_error"), 4), fmt(s.get("ate_rmse"), 4), fmt(s.get("points"), 0),
            len(r.get("runs", []))))
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(prog="sweep_selection", description=__doc__.split("\n")[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, help="an evaluate_colmap --out folder with an exhaustive run")
    p.add_argument("--setting", default="default", help="default or relaxed (which exhaustive database)")
    p.add_argument("--tools", required=True, help="folder with select_views and evaluate_trajectory")
    p.add_argument("--variant", action="append", default=[], help="LABEL:SPEC (see below)")
    p.add_argument("--variants-file", help="a file of LABEL:SPEC lines")
    p.add_argument("--repeats", type=int, default=1, help="mapper runs per variant (default 1)")
    p.add_argument("--threads", type=int, default=-1, help="Mapper.num_threads (default -1: all cores)")
    p.add_argument("--select-only", action="store_true",
                   help="run select_views and count pairs and verified pairs, no mapping")
    p.add_argument("--keep-models", action="store_true", help="keep each run's sparse model (default: text only)")
    p.add_argument("--colmap", default="colmap")
    p.add_argument("--out", default="", help="where to write (default RUN/sweep-SETTING)")
    args = p.parse_args(argv)
    variants = list(args.variant)
    if args.variants_file:
        variants += [l.strip() for l in open(args.variants_file) if l.strip() and not l.lstrip().startswith("#")]
    if not variants:
        p.error("no --variant and no --variants-file")

    run_dir = os.path.abspath(args.run)
    source_db = os.path.join(run_dir, args.setting, "exhaustive", "database.db")
    data = os.path.join(run_dir, "data")
    if not os.path.isfile(source_db):
        print("sweep_selection: error: no exhaustive database at %s" % source_db, file=sys.stderr)
        return 1
    image_path = os.path.join(data, "rgb")
    units = "m" if os.path.isfile(os.path.join(data, "depth.txt")) else "GT units"
    out = os.path.abspath(args.out or os.path.join(run_dir, "sweep-" + args.setting))
    os.makedirs(out, exist_ok=True)
    json_path = os.path.join(out, "sweep.json")
    results = json.load(open(json_path)) if os.path.exists(json_path) else []
    for variant in variants:
        label, _, spec = variant.partition(":")
        spec = spec.strip()
        vdir = os.path.join(out, label)
        shutil.rmtree(vdir, ignore_errors=True)
        os.makedirs(vdir)
        pairs_txt = os.path.join(vdir, "pairs.txt")
        if spec.startswith("@"):
            shutil.copy2(spec[1:], pairs_txt)
        elif spec.startswith("="):
            with Database(os.path.join(run_dir, args.setting, spec[1:], "database.db")) as d:
                pairs = d.matched_names()
            open(pairs_txt, "w").write("".join("%s %s\n" % pr for pr in pairs))
        elif spec.startswith("%sequential"):
            overlap = int(spec.split()[1])
            names = capture_order(data)
            open(pairs_txt, "w").write("".join("%s %s\n" % (names[a], names[b]) for a in range(len(names))
                                               for b in range(a + 1, min(len(names), a + 1 + overlap))))
        else:
            cmd = [os.path.join(args.tools, "select_views"), "--dataset", data, "--every", "1", "--out", vdir,
                   "--quiet", "--print-sets", "0"] + spec.split()
            sel = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            open(os.path.join(vdir, "select_views.log"), "w").write("$ %s\n%s" % (" ".join(cmd), sel.stdout))
            if sel.returncode != 0:
                print("sweep_selection: %s: select_views failed:\n%s" % (label, sel.stdout), file=sys.stderr)
                return 1
        db = os.path.join(vdir, "database.db")
        shutil.copy2(source_db, db)
        with open(pairs_txt) as f:
            wanted = [tuple(line.split()[:2]) for line in f if len(line.split()) >= 2]
        with Database(db) as d:
            kept = d.keep_pairs(wanted)
            counts = d.counts()
        verified, images = counts["pairs_verified"], counts["images"]
        r = {"label": label, "args": spec, "pairs": kept, "verified": verified, "images": images, "runs": []}
        if not args.select_only:
            for k in range(args.repeats):
                rdir = os.path.join(vdir, "run%d" % k)
                os.makedirs(rdir)
                r["runs"].append(map_once(args.colmap, db, image_path, rdir, args.threads, seed=k,
                                          evaluate_trajectory=os.path.join(args.tools, "evaluate_trajectory"),
                                          dataset=data, keep_model=args.keep_models))
            r["summary"] = spread(r["runs"], METRICS)
        os.remove(db)  # a copy of the exhaustive database, rebuilt from pairs.txt when needed
        results = [x for x in results if x["label"] != label] + [r]
        s = r.get("summary", {})
        print("%-28s pairs %4d verified %4d registered %s reproj %s ATE %s  (%s)" % (
            label, r["pairs"], verified, fmt(s.get("registered"), 0, images),
            fmt(s.get("reprojection_error"), 4), fmt(s.get("ate_rmse"), 4), spec), flush=True)
        json.dump(results, open(json_path, "w"), indent=1)
        open(os.path.join(out, "sweep.md"), "w").write(markdown(results, units))
    return 0

