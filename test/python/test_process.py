"""COLMAP's commands as child processes: a cancel is never lost (issue 35). `sleep` stands in
for a COLMAP command that would run for a long time; no COLMAP is needed."""
import subprocess
import time

import pytest

from view_selection.colmap import process
from view_selection.colmap.process import Colmap, ColmapError
from view_selection.colmap.project import ColmapProject, ProjectError


def alive(pid):
    try:
        with open("/proc/%d/stat" % pid) as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_a_cancel_between_the_check_and_the_start_kills_the_command_at_once(monkeypatch, tmp_path):
    """The window of issue 35: the project checked `cancelled`, then another thread cancelled
    before the command's process was known; the cancel must still kill it, not wait for the
    timeout (here 60 s)."""
    project = ColmapProject(str(tmp_path), colmap="sleep")
    started = []
    real_popen = subprocess.Popen

    def popen_then_cancel(*args, **kwargs):
        proc = real_popen(*args, **kwargs)
        started.append(proc)
        project.cancel()  # what the shutdown thread does, in the window
        return proc

    process._death_signal_prefix()  # its probe of setpriv runs before, not through the stand-in
    monkeypatch.setattr(process.subprocess, "Popen", popen_then_cancel)
    t0 = time.monotonic()
    with pytest.raises(ProjectError, match="cancelled"):
        project.run(["60"], "extraction", timeout=60.0)
    assert time.monotonic() - t0 < 20.0  # killed at once, not at the 60 s timeout
    assert len(started) == 1 and started[0].returncode is not None
    assert not alive(started[0].pid)


def test_a_cancel_is_kept_until_the_caller_clears_it(tmp_path):
    colmap = Colmap("sleep")
    colmap.cancel()  # nothing running: nothing killed, but nothing may start either
    with pytest.raises(ColmapError, match="not started"):
        colmap.run(["60"], "matching", timeout=60.0)
    project = ColmapProject(str(tmp_path), colmap="true")
    project.cancel()
    assert project.cancelled
    with pytest.raises(ProjectError, match="cancelled"):
        project.run(["x"], "extraction", timeout=10.0)
    project.cancelled = False
    assert project.run(["x"], "extraction", timeout=10.0) >= 0.0


def test_a_cancel_kills_the_running_command(tmp_path):
    import threading
    colmap = Colmap("sleep")
    running = threading.Event()
    real = colmap._lock

    class Signalling:
        """The lock that guards _running: set `running` once run() has published the process."""

        def __enter__(self):
            return real.__enter__()

        def __exit__(self, *exc):
            out = real.__exit__(*exc)
            if colmap._running is not None:
                running.set()
            return out

    colmap._lock = Signalling()
    result = []
    t = threading.Thread(target=lambda: result.append(pytest.raises(ColmapError, colmap.run, ["60"], "model", 60.0)))
    t0 = time.monotonic()
    t.start()
    assert running.wait(10.0)
    colmap.cancel()
    t.join(20.0)
    assert not t.is_alive() and time.monotonic() - t0 < 20.0
    assert "cancelled" in str(result[0].value)


def test_the_deadline_is_checked_in_process_and_bounds_a_command(tmp_path):
    project = ColmapProject(str(tmp_path), colmap="sleep")
    project.check_deadline("matching")  # no deadline: nothing
    project.deadline = time.monotonic() + 60.0
    project.check_deadline("matching")
    project.deadline = time.monotonic() + 2.5
    t0 = time.monotonic()
    with pytest.raises(ProjectError) as e:
        project.run(["60"], "matching", timeout=60.0)  # killed at the deadline, not at its timeout
    assert e.value.out_of_time and e.value.timed_out and time.monotonic() - t0 < 20.0
    with pytest.raises(ProjectError) as e:
        project.check_deadline("extraction")
    assert e.value.out_of_time and "extraction" in str(e.value)
    with pytest.raises(ProjectError) as e:
        project.run(["1"], "model", timeout=60.0)
    assert e.value.out_of_time and "no time left" in str(e.value)
