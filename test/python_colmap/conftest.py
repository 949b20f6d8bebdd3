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
