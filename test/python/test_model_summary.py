"""model_summary on folders that are not a finished project: a clear error, exit 1 and nothing
written (no model.png, no file touched); and on a small project written here, the figures come
from sparse/0 and the report's skipped items are named. The run on a real project with COLMAP is
in test/python_colmap/test_model_summary_real.py."""
import json
import os

import numpy as np
import pytest

from view_selection.colmap import model as colmap_model
from view_selection.colmap.database import Database
from view_selection.tools import model_summary


def listing(folder):
    """Every file under `folder` with its size and mtime: what a run must leave as it was."""
    out = {}
    for root, _, files in os.walk(str(folder)):
        for name in files:
            st = os.stat(os.path.join(root, name))
            out[os.path.relpath(os.path.join(root, name), str(folder))] = (st.st_size, st.st_mtime_ns)
    return out


def a_model(points=True):
    m = colmap_model.Model({1: colmap_model.Camera(1, "PINHOLE", 64, 48, [50.0, 50.0, 32.0, 24.0])})
    for iid in (1, 2, 3):  # 1 and 2 see the points, 3 sees none
        seen = points and iid < 3
        m.images[iid] = colmap_model.Image(iid, (1.0, 0.0, 0.0, 0.0), (-0.1 * iid, 0.0, 0.0), 1, "rgb/%d.png" % iid,
                                           np.full((8, 2), 10.0) if seen else None,
                                           np.arange(1, 9) if seen else None)
    if points:
        for pid in range(1, 9):
            m.points[pid] = colmap_model.Point3D(pid, (0.01 * pid, 0.02, 2.0), (128, 128, 128), 0.25 * (pid % 3),
                                                 [1, 2], [pid - 1, pid - 1])
    return m


def a_project(folder, points=True, report=True):
    os.makedirs(str(folder / "sparse"))
    colmap_model.write_model(a_model(points), str(folder / "sparse" / "0"))
    with Database(str(folder / "database.db"), create=True):
        pass
    if report:
        (folder / "report.json").write_text(json.dumps({
            "model": "known_poses", "keyframes": 4, "pairs_wasted": 0,
            "skipped": {"images": [{"item": "rgb/4.png", "attempts": 1, "error": "cannot read rgb/4.png"}],
                        "pairs": [{"item": "rgb/1.png rgb/3.png", "attempts": 1, "error": "matches_importer exit 3"}]},
            "matching": {"guided": 2, "images": 3, "fallback": 1}}))
    return folder


def run(capsys, *args):
    code = model_summary.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("case", ["empty", "not_a_folder", "no_points", "no_report", "bad_report"])
def test_bad_input_is_an_error_and_writes_nothing(tmp_path, capsys, case):
    folder = tmp_path / "project"
    if case == "empty":
        os.makedirs(str(folder / "images"))
        expect = "is not a COLMAP project"
    elif case == "not_a_folder":
        folder = tmp_path / "nothing_here"
        expect = "no folder at"
    elif case == "no_points":
        a_project(folder, points=False)
        expect = "has 3 keyframes and no 3D points"
    elif case == "no_report":
        a_project(folder, report=False)
        expect = "has no report.json"
    else:
        a_project(folder)
        (folder / "report.json").write_text('{"model": "known_poses", ')  # cut short
        expect = "cannot read"
    before = listing(tmp_path)
    code, out, err = run(capsys, folder)
    assert code == 1
    assert out == ""
    assert err.startswith("model_summary: error: ") and expect in err, err
    assert listing(tmp_path) == before  # nothing written, nothing touched


def test_a_project_is_summarised_from_its_model_and_report(tmp_path, capsys):
    folder = a_project(tmp_path / "project")
    code, out, err = run(capsys, folder)
    assert code == 0, err
    # The model's own figures: 3 images, 8 points, the mean of the points' errors.
    mean = np.mean([0.25 * (pid % 3) for pid in range(1, 9)])
    assert "keyframes   3 of 4 in the model (2 see its points), 8 3D points, mean reprojection error %.2f px" % mean in out
    assert "2 guided by the poses, 3 by the images' geometry, 1 by COLMAP's matcher" in out
    assert "1 image: rgb/4.png (cannot read rgb/4.png)" in out
    assert "1 pair: rgb/1.png rgb/3.png (matches_importer exit 3)" in out
    assert "refinement  off" in out
    assert (folder / "model.png").stat().st_size > 1000
    assert not [n for n in os.listdir(str(folder)) if n.endswith(".tmp.png")]
    code, out, _ = run(capsys, folder, "--no-picture", "--picture", tmp_path / "x.png")
    assert code == 0 and "picture" not in out and not (tmp_path / "x.png").exists()
