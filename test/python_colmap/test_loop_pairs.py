"""Pairs across revisits the poses do not show (matching/loops.py), with the real COLMAP and
refine_model, through colmap_from_selection: the built-in walk twice round the room with a strong
seeded drift, so that its second lap's poses no longer meet the first lap's where the camera comes
back. The loop pairs verify, and the refined model with them is far closer to the exact poses
than without them, where the selection alone leaves the drift unobservable."""
import json
import sqlite3

import numpy as np

from conftest import colmap_from_selection, run, tool
from view_selection import geometry
from view_selection.colmap.model import read_model
from view_selection.evaluation.trajectory import ate_rmse
from view_selection.export_folder import ExportFolder
from view_selection.refinement import drift


def verified_across(database, order, gap):
    """Verified pairs (15 inliers or more) of keyframes at least `gap` apart in `order` (stamps)."""
    con = sqlite3.connect(str(database))
    names = dict(con.execute("SELECT image_id, name FROM images"))
    n = 0
    for pair_id, rows in con.execute("SELECT pair_id, rows FROM two_view_geometries"):
        b = pair_id % 2147483647
        a = (pair_id - b) // 2147483647
        n += rows >= 15 and abs(order[names[a]] - order[names[b]]) >= gap
    con.close()
    return n


def test_loop_pairs_let_the_refinement_close_the_loop(tmp_path):
    walk, posed, selection = (str(tmp_path / n) for n in ("walk", "posed", "selection"))
    # 600 frames at QVGA, 15 Hz, 0.35 m/s: twice round the room in 40 s (about 120 keyframes).
    # The drift (0.6 deg and 10% of each step, seed 0; 158 mm ATE) is far beyond the shipped
    # sequences' so that the selection on the drifting poses misses most revisits. The node's
    # revisit rule recognises the second lap from the images (~revisit_registration) and makes
    # few keyframes on it; those made where a recognised revisit ends name the keyframe revisited
    # (revisit_of), which loops.py pairs. Measured: 211 mm refined without loop pairs, 4.91 mm with
    # them (7, 6 from revisit_of); seeds 1 and 2: 5.02 and 5.21 mm (docs/design.md).
    run([tool("generate_sequence"), "--out", walk, "--frames", "600", "--width", "320", "--height", "240",
         "--fps", "15", "--speed", "0.35", "--quiet"], timeout=600)
    exact_rows, _ = drift.drifted_tum_folder(walk, posed, translation_ratio=0.1, rotation_deg=0.6, seed=0)
    run([tool("select_views"), "--dataset", posed, "--out", selection, "--quiet", "--print-sets", "0"], timeout=600)
    export = ExportFolder(selection)
    by_stamp = {round(s, 6): np.array(c) for s, c, _ in exact_rows}
    exact = {k.name: by_stamp[round(k.stamp, 6)] for k in export.keyframes}
    stamps = {k.name: k.stamp for k in export.keyframes}

    def ate(path):
        images = list(read_model(path).images.values())
        return ate_rmse([geometry.centre_of(im.qvec, im.tvec) for im in images], [exact[im.name] for im in images])

    results = {}
    for name, flags in (("loops", []), ("none", ["--no-loop-pairs"])):
        out = tmp_path / name
        colmap_from_selection(selection, "--model", "known_poses", "--out", out, *flags)
        with open(out / "report.json") as f:
            report = json.load(f)
        results[name] = (report, ate(str(out / "sparse" / "0")), ate(str(out / "sparse" / "unrefined")))
    report, with_loops, drifted = results["loops"]
    none, without, _ = results["none"]
    assert drifted > 0.1  # the drift is there
    assert report["loop_pairs"] > 0 and none["loop_pairs"] == 0
    assert report["loop_pairs_verified"] >= report["loop_pairs"] // 2, report
    assert report["loop_pairs_from_revisits"] > 0, report  # the node's revisit_of links are paired
    assert report["pairs_lost"] == [] and report["final_pairs_matched"] == report["final_pairs"]
    # the verified pairs across a revisit (10 s apart or more: a lap takes 20 s): the loop pairs'
    # are there, and more of them than the selection found alone
    across = {name: verified_across(tmp_path / name / "database.db", stamps, 10.0) for name in results}
    assert across["loops"] >= report["loop_pairs_verified"] > 0
    assert across["loops"] > across["none"]
    print("ATE drifting %.1f mm, refined with %d loop pairs %.2f mm, without %.2f mm"
          % (1e3 * drifted, report["loop_pairs"], 1e3 * with_loops, 1e3 * without))
    assert with_loops < 0.25 * drifted
    assert with_loops < 0.5 * without
