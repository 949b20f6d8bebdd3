"""One run of COLMAP's mapper on a database, measured: the largest model's statistics and its ATE
against a TUM folder's ground truth (the C++ evaluate_trajectory). evaluate_colmap and
sweep_selection map this way; repeated runs (seed k for run k) are summarised by median and
spread, since the mapper varies between runs."""
import json
import os
import statistics
import subprocess

from ..colmap.model import read_model, write_model
from ..colmap.process import Colmap, ColmapError


def map_once(colmap, database, image_path, out_dir, threads=-1, seed=0, suffix="", evaluate_trajectory=None,
             dataset=None, keep_model=True, timeout=3600.0):
    """`colmap mapper` into out_dir/sparse<suffix>; returns {seed, mapping_seconds, models, model,
    registered, points, observations, track_length, obs_per_image, reprojection_error[, ate_rmse,
    ate_median, ate_scale]} or with 'error' (registered 0) when the mapper made no model."""
    result = {"seed": seed}
    sparse = os.path.join(out_dir, "sparse" + suffix)
    os.makedirs(sparse, exist_ok=True)
    runner = Colmap(colmap, os.path.join(out_dir, "colmap.log"))
    try:
        result["mapping_seconds"] = runner.run(
            ["mapper", "--random_seed", seed, "--database_path", database, "--image_path", image_path,
             "--output_path", sparse, "--Mapper.num_threads", threads], "mapping", timeout)
    except ColmapError:
        with open(runner.log_path) as f:
            text = f.read().rsplit("$ ", 1)[-1]
        reason = "no good initial image pair" if "No good initial image pair" in text else ""
        result.update(error="mapper failed" + (": " + reason if reason else ""), registered=0)
        return result
    models = sorted((d for d in os.listdir(sparse) if d.isdigit()), key=int)
    result["models"] = len(models)
    if not models:
        result.update(error="the mapper made no model", registered=0)
        return result
    read = {m: read_model(os.path.join(sparse, m)) for m in models}
    stats = {m: read[m].statistics() for m in models}
    best = max(models, key=lambda m: (stats[m]["registered"], stats[m]["points"], -int(m)))
    result["model"] = best
    result.update(stats[best])
    if evaluate_trajectory and dataset:
        txt = os.path.join(out_dir, "model_txt" + suffix)
        write_model(read[best], txt, binary=False)
        ate_json = os.path.join(out_dir, "ate%s.json" % suffix)
        done = subprocess.run([evaluate_trajectory, "--model", txt, "--dataset", dataset, "--json", ate_json],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True, timeout=600)
        with open(os.path.join(out_dir, "evaluate_trajectory%s.log" % suffix), "w") as f:
            f.write(done.stdout)
        if done.returncode != 0:
            lines = done.stdout.strip().splitlines()
            result["ate_error"] = lines[-1] if lines else "evaluate_trajectory failed"
        else:
            with open(ate_json) as f:
                ate = json.load(f)
            result.update(ate_rmse=ate["ate"]["rmse"], ate_median=ate["ate"]["median"],
                          ate_scale=ate["alignment"]["scale"])
    if not keep_model:
        import shutil
        shutil.rmtree(sparse, ignore_errors=True)
    return result


def spread(runs, keys):
    """{key: {median, min, max, n}} over repeated runs; a failed run counts as 0 registered."""
    out = {}
    for key in keys:
        values = [r.get("registered", 0) for r in runs] if key == "registered" else \
            [r[key] for r in runs if r.get(key) is not None]
        if values:
            out[key] = {"median": statistics.median(values), "min": min(values), "max": max(values), "n": len(values)}
    return out
