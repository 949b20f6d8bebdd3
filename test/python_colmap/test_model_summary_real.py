"""model_summary on a real project (colmap_from_selection --model known_poses, the real COLMAP)
with an image that cannot be read and a pair COLMAP's matcher fails on every time: the summary
names both, with why, and draws model.png; the figures are the model's. The bad inputs (not a
project, a model without points, no report.json) are in test/python/test_model_summary.py."""
import json
import os
import shutil
import stat
import sys

import cv2
import numpy as np

from conftest import REPO, colmap_from_selection, run, walk_selection
from view_selection.colmap.model import read_model

# A COLMAP that fails matches_importer whenever its list holds the first pair it was asked for
# with the turned keyframe: one pair that COLMAP can never match (a crash on one item).
STAND_IN = '''#!%s
import os, sys
here = os.path.dirname(os.path.abspath(__file__))
args = sys.argv[1:]
if args and args[0] == "matches_importer":
    listed = [" ".join(l.split()) for l in open(args[args.index("--match_list_path") + 1]) if l.strip()]
    bad = os.path.join(here, "bad_pair.txt")
    if not os.path.exists(bad):
        with open(bad, "w") as f:
            f.write([p for p in listed if os.environ["TURNED"] in p.split()][0])
    if open(bad).read() in listed:
        print("simulated: matching crashed", file=sys.stderr)
        sys.exit(3)
os.execvp("colmap", ["colmap"] + args)
'''


def test_the_summary_names_a_skipped_image_and_a_skipped_pair(tmp_path):
    sequence, selection = walk_selection(tmp_path, 60)
    doc = json.load(open(str(selection / "selection.json")))
    keyframes = doc["keyframes"]
    assert len(keyframes) == 10
    images = tmp_path / "images"
    shutil.copytree(str(sequence / doc["params"].get("image_path", "rgb")), str(images))
    unreadable, turned = keyframes[3]["image"], keyframes[7]
    (images / unreadable).write_bytes(b"\x89PNG\r\n\x1a\n but not an image")
    # keyframe 7 at keyframe 6's place: no baseline between their poses, so their pair falls back
    # to COLMAP's matcher (a turned pose alone is matched by the images' geometry now, and a blank
    # image's pairs are left unverified without COLMAP: fewer features than it could verify)
    turned["position"] = list(keyframes[6]["position"])
    with open(str(selection / "selection.json"), "w") as f:
        json.dump(doc, f)
    stand_in = tmp_path / "colmap_stand_in" / "colmap"
    stand_in.parent.mkdir()
    stand_in.write_text(STAND_IN % sys.executable)
    stand_in.chmod(stand_in.stat().st_mode | stat.S_IXUSR)
    os.environ["TURNED"] = turned["image"]
    try:
        # Exit 3: the unreadable image's pairs and the pair COLMAP fails on are wanted and not in
        # the model (issue 34); the model is built all the same.
        colmap_from_selection(selection, "--model", "known_poses", "--image-path", images, "--out",
                              tmp_path / "model", "--threads", "2", "--colmap", stand_in, expect=3)
    finally:
        del os.environ["TURNED"]
    bad_pair = (stand_in.parent / "bad_pair.txt").read_text()
    report = json.load(open(str(tmp_path / "model" / "report.json")))
    assert [s["item"] for s in report["skipped"]["pairs"]] == [bad_pair]  # the project did skip exactly it

    out = run([sys.executable, os.path.join(REPO, "scripts", "model_summary"), str(tmp_path / "model")])
    lines = out.splitlines()
    skipped = [l for l in lines if l.startswith("skipped")]
    assert skipped and ("1 image: %s (" % unreadable) in skipped[0] and "cannot read" in skipped[0], out
    pair_line = [l for l in lines if ("1 pair: %s (" % bad_pair) in l]
    assert pair_line and "exit 3" in pair_line[0], out
    model = read_model(str(tmp_path / "model" / "sparse" / "0"))
    stats = model.statistics()
    seeing = sum(1 for im in model.images.values() if (im.point3D_ids >= 0).any())
    assert seeing < len(model.images)  # the unreadable image is in the model, without points
    assert ("keyframes   %d of 10 in the model (%d see its points), %d 3D points, mean reprojection error %.2f px"
            % (stats["registered"], seeing, stats["points"], stats["reprojection_error"])) in out, out
    m = report["matching"]
    assert m["fallback"] >= 1
    assert "%d guided by the poses, %d by the images' geometry, %d by COLMAP's matcher" % (
        m["guided"], m["images"], m["fallback"]) in out
    assert any(l.startswith("refinement  %s: %d keyframes moved" % (report["refinement"]["status"],
                                                                    report["refinement"]["keyframes_refined"]))
               for l in lines), out
    picture = tmp_path / "model" / "model.png"
    assert picture.stat().st_size > 1000
    drawn = cv2.imread(str(picture))
    assert drawn is not None and np.ptp(drawn) > 100  # a picture, not a blank
