import math
import os
import shutil
import subprocess

import numpy as np
import pytest

from view_selection import geometry
from view_selection.evaluation import trajectory


def test_umeyama_recovers_a_similarity():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(20, 3))
    r = geometry.rotation_of((0.8, 0.2, -0.5, 0.1))
    y = (2.5 * (r @ x.T)).T + [1.0, -2.0, 0.5]
    s, r_est, t = trajectory.umeyama(x, y)
    assert s == pytest.approx(2.5) and np.allclose(r_est, r) and np.allclose(t, [1.0, -2.0, 0.5])
    assert trajectory.ate_rmse(x, y) == pytest.approx(0.0, abs=1e-9)


def test_ate_is_the_rmse_of_what_a_similarity_cannot_explain():
    rng = np.random.default_rng(4)
    y = rng.normal(size=(200, 3)) * 3
    noise = rng.normal(size=(200, 3)) * 0.01
    x = (0.5 * (y + noise))  # scaled, with noise
    assert trajectory.ate_rmse(x, y) == pytest.approx(math.sqrt((noise ** 2).sum(axis=1).mean()), rel=0.05)
    assert trajectory.ate_rmse(x, y, with_scale=False) > 1.0  # without the scale it cannot fit


def test_degenerate_sets_give_nan_not_zero():
    assert math.isnan(trajectory.ate_rmse([[0, 0, 0], [1, 1, 1]], [[0, 0, 0], [1, 1, 1]]))
    line = [[i, 0, 0] for i in range(5)]
    assert math.isnan(trajectory.ate_rmse(line, line))
    with pytest.raises(ValueError):
        trajectory.umeyama(line, line)


def evaluate_trajectory_tool():
    found = shutil.which("evaluate_trajectory")
    tools = os.environ.get("VIEW_SELECTION_TOOLS_DIR")
    if tools and os.path.isfile(os.path.join(tools, "evaluate_trajectory")):
        found = os.path.join(tools, "evaluate_trajectory")
    return found


def test_agrees_with_the_cpp_evaluate_trajectory(tmp_path):
    """The package's C++ ATE (eval/trajectory_alignment) and this one, on one model."""
    tool = evaluate_trajectory_tool()
    if not tool:
        pytest.skip("evaluate_trajectory is not built (VIEW_SELECTION_TOOLS_DIR)")
    from view_selection.colmap import model as cm
    from view_selection.evaluation import tum
    rng = np.random.default_rng(5)
    m = cm.Model(cameras={1: cm.Camera(1, "PINHOLE", 64, 48, (50, 50, 32, 24))})
    truth, estimated, poses = [], [], []
    for i in range(12):
        c = np.array([math.cos(i / 2.0), math.sin(i / 2.0), 0.1 * i])
        q = geometry.quaternion_of(geometry.rotation_of((1, 0.1 * i, 0.05, 0)))
        poses.append((1000.0 + i, tuple(c), q))
        est = 3.0 * c + rng.normal(size=3) * 0.02
        qv, tv = geometry.world_to_camera(est, q)
        m.images[i + 1] = cm.Image(i + 1, qv, tv, 1, "%.6f.png" % (1000.0 + i))
        truth.append(c)
        estimated.append(est)
    cm.write_model(m, str(tmp_path / "model"), binary=False)
    tum.write_trajectory(str(tmp_path / "groundtruth.txt"), poses)
    out = subprocess.run([tool, "--model", str(tmp_path / "model"), "--groundtruth", str(tmp_path / "groundtruth.txt")],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True, timeout=60)
    assert out.returncode == 0, out.stdout
    values = dict(line.split()[:2] for line in out.stdout.splitlines() if len(line.split()) >= 2)
    rmse_key = [k for k in values if "rmse" in k][0]
    assert float(values[rmse_key]) == pytest.approx(trajectory.ate_rmse(estimated, truth), rel=1e-6)
