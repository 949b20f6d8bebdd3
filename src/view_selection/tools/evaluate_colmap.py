"""Reproduce the paper's experiment: view selection strategies against COLMAP's matchers.

Given a TUM-layout folder (rgb.txt, groundtruth.txt, camera.yaml, optional depth.txt), it takes
every (interval+1)-th frame, runs COLMAP feature extraction once (PINHOLE camera with the
folder's known intrinsics, one camera, CPU), then for each strategy copies the feature database,
matches, runs `colmap mapper`, and records pairs, matching and mapping time, registered images,
3D points, mean track length, mean reprojection error and the absolute trajectory error (Sim(3)
Umeyama alignment to groundtruth.txt, by the evaluate_trajectory tool).

Strategies:
  exhaustive      colmap exhaustive_matcher (every pair)
  sequential      colmap sequential_matcher (default overlap, image-name order)
  nearest         select_views --strategy nearest (k nearest centres within an angle limit)
  ours            select_views with its defaults (plus --select-args and --ours-args), imported
                  with matches_importer
  ours-paper      select_views --gate paper --completion paper (--paper-args): the paper's method
  ours-reachable  select_views --completion reachable, imported with matches_importer
  ours-tuned      select_views --completion reachable plus --tuned-args (default
                  "--min-covisible-ratio 0.5": a co-visibility gate that keeps pairs matchable)

Matching settings (--matching): `default` is COLMAP's; `relaxed` is the paper's wide-baseline
setting (--SiftMatching.min_num_inliers 15 --SiftMatching.min_inlier_ratio 0.1).

The mapper varies from run to run (RANSAC, the initial pair): --repeats N maps each strategy's
database N times, run k with --random_seed k (one thread and one seed give the same model); the tables then give the median and [min-max] of registered images,
reprojection error, ATE and 3D points, and results.json keeps every run. --reuse-matches keeps
the databases of an earlier run in the same --out and only maps again (to add repeats).

Output in --out: results.json, results.md (a Markdown table per setting) and results.png (bars).
Run with /usr/bin first on PATH (Debian's python3 and colmap). Example:

  rosrun view_selection evaluate_colmap --dataset ../shared/data/redkitchen-0-499 --interval 9 \\
      --tools /path/to/build/devel/lib/view_selection --out /tmp/eval-kitchen50
"""

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import time

from ..colmap.database import Database
from ..colmap.process import Colmap, ColmapError
from ..evaluation.mapping import map_once
from ..evaluation.tum import TumError, read_camera_yaml, read_list

STRATEGIES = ["exhaustive", "sequential", "nearest", "ours", "ours-paper", "ours-reachable", "ours-tuned"]
SELECTED = ("nearest", "ours", "ours-paper", "ours-reachable", "ours-tuned")
REPEATED = ("registered", "points", "track_length", "reprojection_error", "ate_rmse", "ate_median")
RELAXED = ["--SiftMatching.min_num_inliers", "15", "--SiftMatching.min_inlier_ratio", "0.1"]


class EvalError(Exception):
    pass


def run(cmd, log_path):
    """A COLMAP command (cmd[0] is the executable) with its output in log_path; its seconds."""
    try:
        return Colmap(cmd[0], log_path, default_timeout=24 * 3600.0).run(cmd[1:], cmd[1])
    except ColmapError as e:
        raise EvalError(str(e))


def log(msg):
    print("[evaluate_colmap %s] %s" % (time.strftime("%H:%M:%S"), msg), file=sys.stderr, flush=True)


def capture(cmd, env=None):
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True)
    return proc.returncode, proc.stdout


def find_tool(name, tools_dir):
    candidates = []
    if tools_dir:
        candidates.append(os.path.join(tools_dir, name))
    # rosrun's script (devel relay or install space) sits beside the C++ tools; in a checkout
    # they are in the build folder beside it (scripts/build_dir.bash).
    from ..ros_session import DEFAULT_BUILD_DIR
    candidates += [os.path.join(os.path.dirname(os.path.abspath(sys.argv[0])), name),
                   os.path.join(DEFAULT_BUILD_DIR, "devel", "lib", "view_selection", name)]
    for c in candidates:
        if os.path.isfile(c) and os.access(c, os.X_OK):
            return os.path.abspath(c)
    found = shutil.which(name)
    if found:
        return found
    raise EvalError("cannot find the '%s' tool; build the package and pass --tools DIR "
                    "(the folder with select_views and evaluate_trajectory)" % name)


def build_subset(args, out):
    """Folder out/data in TUM layout holding only the chosen frames (images copied)."""
    src = os.path.abspath(args.dataset)
    for name in ("rgb.txt", "groundtruth.txt", "camera.yaml"):
        if not os.path.isfile(os.path.join(src, name)):
            raise EvalError("'%s' has no %s; a TUM-layout folder is needed" % (args.dataset, name))
    rgb = read_list(os.path.join(src, "rgb.txt"))
    if args.start >= len(rgb):
        raise EvalError("--start %d but rgb.txt lists %d frames" % (args.start, len(rgb)))
    step = args.every if args.every else args.interval + 1
    chosen = rgb[args.start::step]
    if args.max_images:
        chosen = chosen[:args.max_images]
    if len(chosen) < 3:
        raise EvalError("only %d frames chosen; at least 3 are needed" % len(chosen))
    data = os.path.join(out, "data")
    if os.path.exists(data):
        shutil.rmtree(data)
    os.makedirs(data)
    dirs = {os.path.dirname(r[1]) for r in chosen}
    if len(dirs) != 1:
        raise EvalError("the chosen rgb images are in several folders (%s); one is needed" % sorted(dirs))
    image_dir = dirs.pop()
    for r in chosen:
        dst = os.path.join(data, r[1])
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        shutil.copy2(os.path.join(src, r[1]), dst)
    with open(os.path.join(data, "rgb.txt"), "w") as f:
        f.write("# colour images: every %d-th frame of %s from %d\n" % (step, args.dataset, args.start))
        for r in chosen:
            f.write("%s %s\n" % (r[0], r[1]))
    for name in ("groundtruth.txt", "camera.yaml"):
        shutil.copy2(os.path.join(src, name), os.path.join(data, name))
    has_depth = os.path.isfile(os.path.join(src, "depth.txt"))
    if has_depth:
        shutil.copy2(os.path.join(src, "depth.txt"), os.path.join(data, "depth.txt"))
        for r in read_list(os.path.join(src, "depth.txt")):
            dst = os.path.join(data, r[1])
            if not os.path.lexists(dst):
                os.makedirs(os.path.dirname(dst), exist_ok=True)
                os.symlink(os.path.join(src, r[1]), dst)
    return {"folder": data, "image_path": os.path.join(data, image_dir), "names": [os.path.basename(r[1]) for r in chosen],
            "step": step, "has_depth": has_depth}


def make_pairs(strategy, args, subset, tools, out):
    """Runs select_views for a pair strategy; returns (pairs.txt, seconds, summary text)."""
    pdir = os.path.join(out, "pairs", strategy)
    os.makedirs(pdir, exist_ok=True)
    cmd = [tools["select_views"], "--dataset", subset["folder"], "--every", "1", "--out", pdir, "--quiet",
           "--print-sets", "0"]
    if strategy == "nearest":
        cmd += ["--strategy", "nearest", "--nearest-k", str(args.nearest_k),
                "--nearest-max-angle", str(args.nearest_max_angle)]
    elif strategy == "ours-tuned":
        cmd += ["--k", str(args.k), "--completion", "reachable"] + args.select_args + args.tuned_args
    elif strategy == "ours":
        cmd += args.select_args + args.ours_args
    elif strategy == "ours-paper":
        cmd += ["--k", str(args.k)] + args.select_args + args.paper_args
    else:
        cmd += ["--k", str(args.k), "--completion", strategy.split("-")[1]] + args.select_args
    start = time.monotonic()
    code, text = capture(cmd)
    seconds = time.monotonic() - start
    with open(os.path.join(pdir, "select_views.log"), "w") as f:
        f.write("$ %s\n%s" % (" ".join(cmd), text))
    if code != 0:
        raise EvalError("select_views failed for %s:\n%s" % (strategy, text))
    pairs = os.path.join(pdir, "pairs.txt")
    names = set()
    with open(pairs) as f:
        for line in f:
            names.update(line.split())
    unknown = names - set(subset["names"])
    if unknown:
        raise EvalError("%s names images COLMAP does not have: %s" % (pairs, sorted(unknown)[:3]))
    m = re.search(r"keyframes\s+([0-9]+)", text)
    if m and int(m.group(1)) != len(subset["names"]):
        log("warning: select_views kept %s keyframes of %d images (frames without depth or pose?)"
            % (m.group(1), len(subset["names"])))
    return pairs, seconds, text


def evaluate_strategy(strategy, setting, args, subset, tools, out, features_db, pair_files, earlier):
    rdir = os.path.join(out, setting, strategy)
    db = os.path.join(rdir, "database.db")
    logp = os.path.join(rdir, "colmap.log")
    result = {"strategy": strategy, "setting": setting, "images": len(subset["names"])}
    before = next((r for r in earlier if r["strategy"] == strategy and r["setting"] == setting), None)
    if strategy in pair_files:
        seconds = pair_files[strategy][1]
        result["selection_seconds"] = seconds if seconds is not None else (before or {}).get("selection_seconds")
    if args.reuse_matches and os.path.isfile(db):
        log("%s/%s: reusing the matches in %s" % (setting, strategy, db))
        if before and "matching_seconds" in before:
            result["matching_seconds"] = before["matching_seconds"]
        for name in os.listdir(rdir):
            if name.startswith("sparse") or name.startswith("model_txt") or name.startswith("ate"):
                path = os.path.join(rdir, name)
                shutil.rmtree(path) if os.path.isdir(path) else os.remove(path)
    else:
        if os.path.exists(rdir):
            shutil.rmtree(rdir)
        os.makedirs(rdir)
        shutil.copy2(features_db, db)
        match_opts = ["--SiftMatching.use_gpu", "0", "--SiftMatching.num_threads", str(args.threads)]
        if setting == "relaxed":
            match_opts += RELAXED
        if strategy == "exhaustive":
            cmd = [args.colmap, "exhaustive_matcher", "--database_path", db] + match_opts
        elif strategy == "sequential":
            cmd = [args.colmap, "sequential_matcher", "--database_path", db] + match_opts
        else:
            cmd = [args.colmap, "matches_importer", "--database_path", db, "--match_list_path",
                   pair_files[strategy][0], "--match_type", "pairs"] + match_opts
        log("%s/%s: matching" % (setting, strategy))
        result["matching_seconds"] = run(cmd, logp)
    with Database(db) as d:
        counts = d.counts()
    result["pairs"], result["verified_pairs"] = counts["pairs_matched"], counts["pairs_verified"]
    runs = []
    for k in range(args.repeats):
        suffix = "" if args.repeats == 1 else "-%d" % k
        log("%s/%s: mapping%s (%d pairs matched, %d verified)" % (
            setting, strategy, " run %d of %d" % (k + 1, args.repeats) if args.repeats > 1 else "",
            result["pairs"], result["verified_pairs"]))
        runs.append(map_once(args.colmap, db, subset["image_path"], rdir, args.threads, seed=k, suffix=suffix,
                             evaluate_trajectory=tools["evaluate_trajectory"], dataset=subset["folder"]))
    result["runs"] = runs
    summarise(result, runs)
    return result


def summarise(result, runs):
    """Top-level figures of a strategy: the run itself (one run) or medians, with a spread."""
    if len(runs) == 1:
        result.update(runs[0])
        return
    result["mapping_seconds"] = statistics.median([r.get("mapping_seconds", 0.0) for r in runs])
    spread = {}
    for key in REPEATED:
        values = [r.get(key, 0) if key == "registered" else r.get(key) for r in runs]
        values = [v for v in values if v is not None]
        if values:
            result[key] = statistics.median(values)
            spread[key] = [min(values), max(values), len(values)]
    result["spread"] = spread
    result["models"] = statistics.median([r.get("models", 0) for r in runs])
    failed = [r["error"] for r in runs if "error" in r]
    if failed:
        result["failed_runs"] = len(failed)
        if len(failed) == len(runs):
            result["error"] = failed[0]
    if "ate_rmse" not in result:
        errors = [r["ate_error"] for r in runs if "ate_error" in r]
        if errors:
            result["ate_error"] = errors[0]


def fmt(v, digits=3):
    if v is None:
        return "-"
    if isinstance(v, int):
        return str(v)
    if abs(v) >= 1000:
        return "%.0f" % v
    return ("%." + str(digits) + "g") % v


def no_result(r):
    """Why a row has no ATE, without file paths (the table is meant to be committed)."""
    text = r.get("ate_error") or r.get("error") or "-"
    if text.startswith("'colmap mapper' failed"):
        text = "mapper failed"
    return re.sub(r"(/[^\s/]+)+/?", "...", text)


def cell(r, key, digits=3):
    """A figure with its [min-max] over repeated mapper runs, when there were several."""
    v = r.get(key)
    if v is None:
        return "-"
    text = fmt(v, digits) if not isinstance(v, float) or not v.is_integer() else fmt(int(v), digits)
    spread = r.get("spread", {}).get(key)
    if spread and spread[0] != spread[1]:
        lo, hi = (fmt(int(x), digits) if float(x).is_integer() else fmt(x, digits) for x in spread[:2])
        text += " [%s-%s]" % (lo, hi)
    return text


def markdown(results, title, units):
    lines = ["### %s" % title, ""]
    runs = max(len(r.get("runs", [])) for r in results) if results else 1
    if runs > 1:
        lines += ["Medians of %d mapper runs on each strategy's matches, [min-max] where they differ." % runs, ""]
    header = ("| setting | strategy | pairs matched | verified | matching [s] | mapping [s] | registered | "
              "3D points | track length | reproj. error [px] | ATE RMSE [%s] | models |" % units)
    lines += [header, "|" + "---|" * 12]
    for r in results:
        reg = "%s/%s" % (cell(r, "registered"), r["images"])
        if r.get("failed_runs"):
            reg += " (%d of %d runs failed)" % (r["failed_runs"], len(r["runs"]))
        lines.append("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
            r["setting"], r["strategy"], r.get("pairs", "-"), r.get("verified_pairs", "-"),
            fmt(r.get("matching_seconds")), fmt(r.get("mapping_seconds")), reg, cell(r, "points"),
            cell(r, "track_length"), cell(r, "reprojection_error", 4),
            (cell(r, "ate_rmse", 4) + ("" if r.get("registered") == r["images"] else " (on %s)" % cell(r, "registered")))
            if "ate_rmse" in r else no_result(r),
            r.get("models", "-")))
    lines.append("")
    return "\n".join(lines)


def chart(results, path, title, units):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    settings = sorted({r["setting"] for r in results}, key=lambda s: ["default", "relaxed"].index(s))
    strategies = [s for s in STRATEGIES if any(r["strategy"] == s for r in results)]
    metrics = [("pairs", "pairs matched"), ("matching_seconds", "matching time [s]"),
               ("registered", "registered images"), ("reprojection_error", "mean reprojection error [px]"),
               ("ate_rmse", "ATE RMSE [%s]" % units), ("points", "3D points")]
    fig, axes = plt.subplots(2, 3, figsize=(15, 8))
    width = 0.8 / max(1, len(settings))
    colours = ["#4c72b0", "#dd8452"]
    for ax, (key, label) in zip(axes.flat, metrics):
        for si, setting in enumerate(settings):
            values = []
            for s in strategies:
                r = next((r for r in results if r["strategy"] == s and r["setting"] == setting), {})
                values.append(r.get(key) if r.get(key) is not None else 0)
            xs = [i + (si - (len(settings) - 1) / 2) * width for i in range(len(strategies))]
            bars = ax.bar(xs, values, width, label=setting, color=colours[si % 2])
            for b, v in zip(bars, values):
                ax.annotate(fmt(v), (b.get_x() + b.get_width() / 2, b.get_height()), ha="center", va="bottom",
                            fontsize=7)
        ax.set_xticks(range(len(strategies)))
        ax.set_xticklabels(strategies, rotation=20, fontsize=8)
        ax.set_title(label, fontsize=10)
        if key == "registered":
            ax.axhline(results[0]["images"], color="grey", linestyle="--", linewidth=0.8)
        if key == "ate_rmse":
            ax.set_xlabel("over the registered images only", fontsize=8)
    axes.flat[0].legend(fontsize=8, title="matching")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(prog="evaluate_colmap", description=__doc__.split("\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    p.add_argument("--dataset", required=True, help="TUM-layout folder")
    p.add_argument("--out", required=True, help="output folder (reused: pairs and runs are redone)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--interval", type=int, default=0,
                   help="frames skipped between chosen frames (the paper's frame gap 0..6): every (interval+1)-th")
    g.add_argument("--every", type=int, help="every N-th frame (same as --interval N-1)")
    p.add_argument("--start", type=int, default=0, help="first frame index in rgb.txt (default 0)")
    p.add_argument("--max-images", type=int, default=0, help="at most this many images (default all)")
    p.add_argument("--strategies", default=",".join(STRATEGIES), help="comma-separated, of: " + ", ".join(STRATEGIES))
    p.add_argument("--matching", default="default", choices=["default", "relaxed", "both"],
                   help="COLMAP's matching defaults, the paper's relaxed settings, or both")
    p.add_argument("--k", type=int, default=5, help="select_views --k for ours-* (default 5)")
    p.add_argument("--nearest-k", type=int, default=5, help="neighbours for nearest (default 5)")
    p.add_argument("--nearest-max-angle", type=float, default=30.0, help="angle limit for nearest [deg] (default 30)")
    p.add_argument("--select-args", default="",
                   help="extra select_views arguments for ours-*, e.g. \"--points features --max-view-angle 20\"")
    p.add_argument("--tuned-args", default="--min-covisible-ratio 0.5",
                   help="select_views arguments added for ours-tuned (default \"--min-covisible-ratio 0.5\")")
    p.add_argument("--ours-args", default="",
                   help="select_views arguments for ours (default none: the tool's defaults)")
    p.add_argument("--paper-args", default="--gate paper --completion paper",
                   help="select_views arguments for ours-paper (default \"--gate paper --completion paper\")")
    p.add_argument("--repeats", type=int, default=1,
                   help="mapper runs per strategy; tables give medians and [min-max] (default 1)")
    p.add_argument("--reuse-matches", action="store_true",
                   help="keep each strategy's database from an earlier run in --out and only map again "
                   "(implies --keep-features)")
    p.add_argument("--keep-features", action="store_true",
                   help="reuse OUT/features.db from an earlier run on the same frames (no extraction)")
    p.add_argument("--max-num-features", type=int, default=0, help="SiftExtraction.max_num_features (default COLMAP's)")
    p.add_argument("--threads", type=int, default=-1, help="COLMAP threads (default -1: all cores)")
    p.add_argument("--colmap", default="colmap", help="the colmap executable (default: colmap on PATH)")
    p.add_argument("--tools", default="", help="folder with select_views and evaluate_trajectory "
                   "(default: PATH, then build_<checkout>/devel/lib/view_selection, as scripts/build)")
    p.add_argument("--title", default="", help="chart and table title (default: the dataset and frames)")
    p.add_argument("--report-only", action="store_true",
                   help="only rewrite results.md and results.png from OUT/results.json")
    args = p.parse_args(argv)
    if args.report_only:
        with open(os.path.join(args.out, "results.json")) as f:
            doc = json.load(f)
        units = "m" if os.path.isfile(os.path.join(args.out, "data", "depth.txt")) else "GT units"
        extraction = doc.get("extraction_seconds")
        md = "%s\n\nFeature extraction (once): %s.\n" % (markdown(doc["results"], doc["title"], units),
                                                         "%.1f s" % extraction if extraction else "reused")
        with open(os.path.join(args.out, "results.md"), "w") as f:
            f.write(md)
        chart(doc["results"], os.path.join(args.out, "results.png"), doc["title"], units)
        print(md)
        return 0
    args.select_args = args.select_args.split()
    args.tuned_args = args.tuned_args.split()
    args.ours_args = args.ours_args.split()
    args.paper_args = args.paper_args.split()
    if args.reuse_matches:
        args.keep_features = True

    try:
        if args.every is not None and args.every < 1:
            raise EvalError("--every must be at least 1")
        if args.interval < 0:
            raise EvalError("--interval must be at least 0")
        strategies = [s.strip() for s in args.strategies.split(",") if s.strip()]
        bad = [s for s in strategies if s not in STRATEGIES]
        if bad or not strategies:
            raise EvalError("unknown strategy %s; choose from %s" % (bad, ", ".join(STRATEGIES)))
        if shutil.which(args.colmap) is None:
            raise EvalError("'%s' not found; install COLMAP (Debian: apt-get install colmap)" % args.colmap)
        tools = {t: find_tool(t, args.tools) for t in ("select_views", "evaluate_trajectory")}
        out = os.path.abspath(args.out)
        os.makedirs(out, exist_ok=True)
        subset = build_subset(args, out)
        cam = read_camera_yaml(os.path.join(subset["folder"], "camera.yaml"))
        n = len(subset["names"])
        title = args.title or "%s, %d images (every %d-th frame)" % (
            os.path.basename(os.path.normpath(args.dataset)), n, subset["step"])
        log("%s -> %s" % (title, out))

        features_db = os.path.join(out, "features.db")
        reuse = args.keep_features and os.path.exists(features_db)
        if reuse:
            with Database(features_db) as d:
                have = sorted(d.image_ids())
            if have != sorted(subset["names"]):
                raise EvalError("--keep-features: %s holds other images than the frames chosen now" % features_db)
        elif os.path.exists(features_db):
            os.remove(features_db)
        extract = [args.colmap, "feature_extractor", "--database_path", features_db, "--image_path",
                   subset["image_path"], "--ImageReader.camera_model", "PINHOLE", "--ImageReader.single_camera", "1",
                   "--ImageReader.camera_params", "%r,%r,%r,%r" % (cam["fx"], cam["fy"], cam["cx"], cam["cy"]),
                   "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", str(args.threads)]
        if args.max_num_features:
            extract += ["--SiftExtraction.max_num_features", str(args.max_num_features)]
        if reuse:
            log("reusing %s" % features_db)
            extraction_seconds = None
        else:
            log("feature extraction on %d images" % n)
            extraction_seconds = run(extract, os.path.join(out, "features.log"))

        pair_files = {}
        for s in strategies:
            if s in SELECTED:
                if args.reuse_matches and os.path.isfile(os.path.join(out, "pairs", s, "pairs.txt")):
                    text = open(os.path.join(out, "pairs", s, "select_views.log")).read()
                    pair_files[s] = (os.path.join(out, "pairs", s, "pairs.txt"), None, text)
                else:
                    pair_files[s] = make_pairs(s, args, subset, tools, out)
        settings = ["default", "relaxed"] if args.matching == "both" else [args.matching]
        results = []
        earlier = []
        earlier_all = []
        if reuse and os.path.exists(os.path.join(out, "results.json")):
            # Keep what an earlier run on the same features measured for other strategies/settings.
            with open(os.path.join(out, "results.json")) as f:
                earlier_doc = json.load(f)
            earlier_all = earlier_doc["results"]
            earlier = [r for r in earlier_doc["results"]
                       if not (r["setting"] in settings and r["strategy"] in strategies)]
            extraction_seconds = earlier_doc.get("extraction_seconds")
        for setting in settings:
            for s in strategies:
                r = evaluate_strategy(s, setting, args, subset, tools, out, features_db, pair_files,
                                      earlier_all)
                results.append(r)
                merged = sorted(earlier + results, key=lambda r: (r["setting"], STRATEGIES.index(r["strategy"])))
                log("%s/%s: %s" % (setting, s, json.dumps({k: r.get(k) for k in (
                    "pairs", "matching_seconds", "registered", "reprojection_error", "ate_rmse", "error")})))
                # Rewrite after every run so an interrupted evaluation keeps what it measured.
                with open(os.path.join(out, "results.json"), "w") as f:
                    json.dump({"title": title, "dataset": args.dataset, "images": n, "step": subset["step"],
                               "extraction_seconds": extraction_seconds, "command": sys.argv,
                               "select_views": {s: pf[2] for s, pf in pair_files.items()},
                               "results": merged}, f, indent=1)
        results = merged
        units = "m" if subset["has_depth"] else "GT units"
        md = "%s\n\nFeature extraction (once): %s.\n" % (markdown(results, title, units), "%.1f s" % extraction_seconds
                                                         if extraction_seconds is not None else "reused")
        with open(os.path.join(out, "results.md"), "w") as f:
            f.write(md)
        chart(results, os.path.join(out, "results.png"), title, units)
        print(md)
        return 0
    except (EvalError, TumError) as e:
        print("evaluate_colmap: error: %s" % e, file=sys.stderr)
        return 1
