# The Python module against the real COLMAP 3.8 and the package's built tools (no ROS master):
# pose-guided matching against COLMAP's own on the shared kitchen, and bad input through
# colmap_from_selection. Run by scripts/test (run_tests_view_selection_pytest_python_colmap), or
# alone with VIEW_SELECTION_TOOLS_DIR set to the build's devel/lib/view_selection.
import os
import shutil
import subprocess
import sys

import pytest

REPO = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
sys.path.insert(0, os.path.join(REPO, "src"))
DATA = os.path.join(os.path.dirname(REPO), "shared", "data")


def tool(name):
    folder = os.environ.get("VIEW_SELECTION_TOOLS_DIR", "")
    path = os.path.join(folder, name)
    if not (folder and os.access(path, os.X_OK)):
        pytest.fail("VIEW_SELECTION_TOOLS_DIR does not hold %s (build the package)" % name)
    return path


def run(cmd, timeout=1800, expect=0):
    env = dict(os.environ, PYTHONPATH=os.path.join(REPO, "src") + ":" + os.environ.get("PYTHONPATH", ""),
               OPENBLAS_NUM_THREADS="1", QT_QPA_PLATFORM="offscreen")
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True,
                          timeout=timeout, env=env)
    assert done.returncode == expect, "%s: exit %d, not %d:\n%s" % (" ".join(cmd), done.returncode, expect,
                                                                     done.stdout[-4000:])
    return done.stdout


def walk_selection(tmp_path, frames):
    """The built-in walk rendered at QVGA (`frames` frames) and its selection with a keyframe
    every 6 frames: (the sequence's folder, the selection's folder)."""
    sequence, selection = tmp_path / "walk", tmp_path / "selection"
    run([tool("generate_sequence"), "--out", str(sequence), "--frames", str(frames), "--width", "320", "--height",
         "240", "--quiet"])
    run([tool("select_views"), "--dataset", str(sequence), "--every", "6", "--out", str(selection), "--quiet",
         "--print-sets", "0"])
    return sequence, selection


def colmap_from_selection(*args, expect=0):
    return run([sys.executable, os.path.join(REPO, "scripts", "colmap_from_selection")] + [str(a) for a in args],
               expect=expect)


def without_real_data(test, folder):
    """Skips, and says so in $VIEW_SELECTION_SKIP_LOG (scripts/test fails when the data is there)."""
    log = os.environ.get("VIEW_SELECTION_SKIP_LOG")
    if log:
        with open(log, "a") as f:
            f.write("%s: no real data (%s absent)\n" % (test, folder))
    pytest.skip("no real data (%s absent)" % folder)


@pytest.fixture(autouse=True)
def needs_colmap():
    if shutil.which("colmap") is None:
        pytest.fail("COLMAP is not installed (scripts/install_deps colmap)")


def drifted_loop(tmp_path):
    """The built-in walk's one loop of the room with the seeded drift, and its selection: 300
    frames at QVGA, 15 Hz, walking at 0.35 m/s (one loop in 20 s, about 55 keyframes, back where
    it started; the frames are those of the default 0.7 m/s at 30 Hz). At half the walk's pace
    the refinement's CPU budget beside the matching (a share of the recording's time) covers the
    whole model a few times during the session (at the default pace it does not keep up over a
    minute: docs/live.md). Returns (the selection's ExportFolder, ate): ate({name: centre}) is
    the ATE against the exact poses of the keyframes named."""
    import numpy as np
    from view_selection.evaluation.trajectory import ate_rmse
    from view_selection.export_folder import ExportFolder
    from view_selection.refinement import drift
    walk, posed, selection = (str(tmp_path / n) for n in ("walk", "posed", "selection"))
    subprocess.run([tool("generate_sequence"), "--out", walk, "--frames", "300", "--width", "320", "--height", "240",
                    "--fps", "15", "--speed", "0.35", "--quiet"], check=True, timeout=600)
    exact_rows, _ = drift.drifted_tum_folder(walk, posed)
    subprocess.run([tool("select_views"), "--dataset", posed, "--out", selection], check=True, timeout=600,
                   stdout=subprocess.DEVNULL)
    export = ExportFolder(selection)
    by_stamp = {round(s, 6): np.array(c) for s, c, _ in exact_rows}
    exact = {k.name: by_stamp[round(k.stamp, 6)] for k in export.keyframes}

    def ate(named):
        names = sorted(n for n in named if n in exact)
        return ate_rmse([named[n] for n in names], [exact[n] for n in names])
    return export, ate


def model_centres(path):
    """{image name: camera centre} of a model folder."""
    import numpy as np
    from view_selection import geometry
    from view_selection.colmap.model import read_model
    return {im.name: np.array(geometry.centre_of(im.qvec, im.tvec)) for im in read_model(path).images.values()}
