"""The refinement after the finish (refinement/afterwards.py): refine_model run for real, in the
background, on a project whose finish could not refine within its budget."""
import os
import shutil
import time

import numpy as np

from view_selection.colmap import model as cm
from view_selection.evaluation.trajectory import ate_rmse
from view_selection.refinement import drift, refiner
from view_selection.refinement.afterwards import RefinementAfterwards

from test_refinement import FakeProject, arc_poses, centres, fake_tool, known_pose_model, refine_tool


def finished_project(tmp_path):
    """A drifted arc's project as a finish left it: sparse/unrefined at the drifting poses,
    sparse/0 the same model (the finish's refinement ran out of time), the database's matches."""
    exact = arc_poses()
    m = known_pose_model(exact, drift.add_drift(exact, 0.02, 0.3, seed=3), np.random.default_rng(29),
                         database=str(tmp_path / "database.db"))
    cm.write_model(m, str(tmp_path / "sparse" / "unrefined"))
    shutil.copytree(str(tmp_path / "sparse" / "unrefined"), str(tmp_path / "sparse" / "0"))
    project = FakeProject(str(tmp_path))
    project.database = str(tmp_path / "database.db")
    return project, str(tmp_path / "sparse" / "0"), [c for c, _ in exact], m


def wait_until_ended(afterwards, timeout=120.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if afterwards.poll():
            return True
        time.sleep(0.05)
    return False


def model_bytes(path):
    return {n: open(os.path.join(path, n), "rb").read() for n in sorted(os.listdir(path))}


def test_only_a_finish_cut_short_by_its_budget_is_refined_afterwards():
    assert RefinementAfterwards.wanted({"status": "out_of_time", "refined": True})
    assert RefinementAfterwards.wanted({"status": "out_of_time", "refined": False})
    for status in ("converged", "no_convergence", "error", "diverged", "nothing_to_refine"):
        assert not RefinementAfterwards.wanted({"status": status}), status
    assert not RefinementAfterwards.wanted(None) and not RefinementAfterwards.wanted({})


def test_it_replaces_the_model_with_what_a_full_refinement_gives(tmp_path):
    project, model_path, truth, given = finished_project(tmp_path)
    tool = refine_tool()
    full = refiner.refine(str(tmp_path / "sparse" / "unrefined"), str(tmp_path / "full"), tool=tool,
                          options=refiner.RefinementOptions(threads=1), database=project.database)
    assert full["status"] == "converged"
    logged = []
    a = RefinementAfterwards(refiner.ModelRefinement(refiner.RefinementOptions(max_seconds=5.0), tool=tool),
                             log=lambda level, text: logged.append((level, text)))
    assert a.start(project, model_path, change=7.0)
    assert a.running is not None and a.change == 7.0
    assert wait_until_ended(a)
    section = a.take()
    assert section is not None, logged
    assert section["status"] == "converged" and section["refined"], section["message"]
    assert section["options"]["max_seconds"] == 0.0 and section["options"]["threads"] == 1
    assert section["matches"] == section["matches_of"] > 0  # a small project: every match
    refined = cm.read_model(model_path)
    assert sorted(refined.images) == sorted(given.images)
    ate = ate_rmse(centres(refined), truth)
    assert ate < 0.5 * ate_rmse(centres(given), truth)
    assert abs(ate - ate_rmse(centres(cm.read_model(str(tmp_path / "full"))), truth)) < 1e-3
    assert a.counts == {"started": 1, "taken": 1, "stopped": 0, "failed": 0}
    assert [n for n in os.listdir(str(tmp_path / "sparse")) if n.startswith(".refine_afterwards_")] == []
    assert a.running is None and a.take() is None


def test_a_run_stopped_leaves_the_finished_model_and_no_process(tmp_path):
    project, model_path, _, _ = finished_project(tmp_path)
    before = model_bytes(model_path)
    tool = fake_tool(tmp_path / "refine_model", "sleep 60")  # a refinement that takes long
    a = RefinementAfterwards(refiner.ModelRefinement(tool=tool), log=lambda level, text: None)
    assert a.start(project, model_path, change=1.0)
    pid = a.running.proc.pid
    assert not a.poll()
    a.stop("a keyframe came")
    assert a.running is None and not a.poll()
    assert a.last == {"status": "stopped", "why": "a keyframe came", "seconds": a.last["seconds"]}
    end = time.monotonic() + 10
    while os.path.exists("/proc/%d" % pid) and time.monotonic() < end:
        time.sleep(0.05)
    assert not os.path.exists("/proc/%d" % pid)
    assert model_bytes(model_path) == before
    assert [n for n in os.listdir(str(tmp_path / "sparse")) if n.startswith(".refine_afterwards_")] == []


def test_a_failing_or_hung_tool_leaves_the_finished_model(tmp_path):
    project, model_path, _, _ = finished_project(tmp_path)
    before = model_bytes(model_path)
    logged = []
    failing = fake_tool(tmp_path / "failing", "exit 3")
    a = RefinementAfterwards(refiner.ModelRefinement(tool=failing), log=lambda level, text: logged.append(text))
    assert a.start(project, model_path, change=1.0)
    assert wait_until_ended(a)
    assert a.take() is None
    assert a.last["status"] == "failed" and "exited with 3" in a.last["error"] and a.counts["failed"] == 1
    assert any("gave nothing" in text for text in logged), logged
    hung = fake_tool(tmp_path / "hung", "sleep 60")
    a = RefinementAfterwards(refiner.ModelRefinement(tool=hung), timeout=0.5, log=lambda level, text: None)
    assert a.start(project, model_path, change=1.0)
    end = time.monotonic() + 10
    while a.running is not None and time.monotonic() < end:
        a.poll()
        time.sleep(0.05)
    assert a.running is None and a.last["status"] == "stopped" and "longer than" in a.last["why"]
    assert model_bytes(model_path) == before


def test_the_strongest_keypoints_matches_keep_tracks_whole():
    rng = np.random.default_rng(4)
    data = np.stack([rng.integers(1, 20, 5000), rng.integers(0, 600, 5000),
                     rng.integers(1, 20, 5000), rng.integers(0, 600, 5000)], axis=1).astype("<i4")
    kept, limit = refiner.strongest_matches(data, 1000)
    assert 0 < len(kept) <= 1000 and limit is not None
    weakest = np.maximum(data[:, 1], data[:, 3])
    # Exactly the matches whose two keypoints are both below the limit: a keypoint is in all of
    # its matches or in none.
    assert np.array_equal(kept, data[weakest < limit])
    assert (weakest < limit + 1).sum() > 1000  # the limit is as high as the cap allows
    same, none = refiner.strongest_matches(data, 5000)
    assert none is None and same is data
    assert refiner.strongest_matches(data, 0)[1] is None
