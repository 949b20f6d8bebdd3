"""COLMAP's commands as child processes: one log, a timeout on every call, a clear error naming
the stage, and children that die with their parent.

A child runs in a process group of its own (a timeout kills the whole group) under
`setpriv --pdeathsig KILL` where util-linux has it, so that a parent killed with SIGKILL does not
leave a COLMAP writing into a database that its successor uses. (preexec_fn would do the same, but
is unsafe in a threaded process such as a rospy node.)
"""
import os
import shutil
import signal
import subprocess
import threading
import time


class ColmapError(Exception):
    """A COLMAP command that could not run, failed or timed out. `stage` names the step."""

    def __init__(self, message, stage=None, timed_out=False):
        super().__init__(message)
        self.stage, self.timed_out = stage, timed_out


def colmap_env():
    """COLMAP's environment: its Qt never looks for a display."""
    env = dict(os.environ)
    env["QT_QPA_PLATFORM"] = "offscreen"
    return env


_SETPRIV = None


def _death_signal_prefix():
    global _SETPRIV
    if _SETPRIV is None:
        path = shutil.which("setpriv")
        ok = False
        if path:
            try:
                ok = subprocess.run([path, "--pdeathsig", "KILL", "--", "true"], stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL, timeout=10).returncode == 0
            except (OSError, subprocess.SubprocessError):
                ok = False
        _SETPRIV = [path, "--pdeathsig", "KILL", "--"] if ok else []
    return list(_SETPRIV)


class Colmap:
    """Runs `colmap <command>` with its output appended to `log_path`.

    seconds: wall time spent per stage (the stage names the caller gives).
    cancelled: set by cancel() and kept until the caller clears it; while it is set, no command
    starts and one that started in the meantime is killed at once (issue 35: a cancel that came
    between a check and the Popen was forgotten, and COLMAP ran to its timeout)."""

    def __init__(self, executable="colmap", log_path=None, default_timeout=600.0):
        self.executable = executable
        self.log_path = log_path
        self.default_timeout = float(default_timeout)
        self.seconds = {}
        self.cancelled = False
        self._running = None  # the Popen of the command running now
        self._lock = threading.Lock()  # cancelled and _running change together

    def available(self):
        return shutil.which(self.executable) is not None

    def run(self, args, stage, timeout=None, capture=False):
        """Runs `colmap args...`; returns the elapsed seconds (and the output, with capture).
        Raises ColmapError when it cannot start, exits non-zero or exceeds `timeout` seconds
        (then the child and its group are killed)."""
        timeout = self.default_timeout if timeout is None else float(timeout)
        cmd = [self.executable] + [str(a) for a in args]
        if self.cancelled:
            raise ColmapError("'%s %s' (%s) not started: cancelled" % (self.executable, args[0], stage), stage)
        start = time.monotonic()
        log = open(self.log_path, "a") if (self.log_path and not capture) else None
        try:
            if log:
                log.write("$ %s\n" % " ".join(cmd))
                log.flush()
            try:
                proc = subprocess.Popen(_death_signal_prefix() + cmd, env=colmap_env(), start_new_session=True,
                                        stdout=subprocess.PIPE if capture else (log or subprocess.DEVNULL),
                                        stderr=subprocess.STDOUT, universal_newlines=capture)
            except OSError as e:
                raise ColmapError("cannot run '%s %s': %s" % (self.executable, args[0], e.strerror or e), stage)
            with self._lock:  # a cancel() before this line sees no process: it is killed here
                self._running = proc
                cancelled = self.cancelled
            if cancelled:
                self._kill(proc)
            try:
                out, _ = proc.communicate(timeout=timeout)
            except subprocess.TimeoutExpired:
                self._kill(proc)
                raise ColmapError("'%s %s' (%s) did not finish within %.0f s and was killed%s"
                                  % (self.executable, args[0], stage, timeout, self._see()), stage, timed_out=True)
            except BaseException:
                self._kill(proc)  # an interrupted parent takes its child with it
                raise
            finally:
                with self._lock:
                    self._running = None
            elapsed = time.monotonic() - start
            if self.cancelled:
                raise ColmapError("'%s %s' (%s) was cancelled" % (self.executable, args[0], stage), stage)
            if log:
                log.write("# exit %d after %.2f s\n" % (proc.returncode, elapsed))
        finally:
            if log:
                log.close()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + elapsed
        if proc.returncode != 0:
            tail = ("\n" + out[-2000:]) if capture and out else self._see()
            raise ColmapError("'%s %s' (%s) failed (exit %d)%s" % (self.executable, args[0], stage, proc.returncode,
                                                                   tail), stage)
        return (elapsed, out) if capture else elapsed

    def cancel(self):
        """Kills the command running now, if any, and any that starts until `cancelled` is
        cleared (from another thread)."""
        with self._lock:
            self.cancelled = True
            proc = self._running
        if proc is not None:
            self._kill(proc)

    def _see(self):
        return "; see %s" % self.log_path if self.log_path else ""

    @staticmethod
    def _kill(proc):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pass
