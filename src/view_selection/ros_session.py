"""A private ROS master and the package's built tools, for the demo, the benchmarks and the soak
(not for the nodes): the build's environment from devel/setup.bash, a master on a free port, the
processes started and stopped without ever hanging, and what the node reports about itself.

The scripts that use it run from a source checkout before any setup.bash is sourced; they put
the checkout's src/ on sys.path to import this module.
"""
import os
import re
import signal
import socket
import subprocess
import time

PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# Beside the checkout, as scripts/build puts it (scripts/build_dir.bash says why).
DEFAULT_BUILD_DIR = os.path.join(os.path.dirname(PACKAGE_DIR), "build_" + os.path.basename(PACKAGE_DIR))
SHARED_DATA = os.path.join(os.path.dirname(PACKAGE_DIR), "shared", "data")
# The topics of a TUM RGB-D bag (and of tum_to_bag --layout tum)
TUM_IMAGE, TUM_DEPTH, TUM_INFO = "/camera/rgb/image_color", "/camera/depth/image", "/camera/rgb/camera_info"
# A core kept busy at normal priority, as a SLAM system keeps one (python3 -c BUSY_LOOP); SIGINT
# ends it without a traceback.
BUSY_LOOP = "import signal\nsignal.signal(signal.SIGINT, signal.SIG_DFL)\nwhile True: pass"


class SessionError(Exception):
    """Something the session needs is missing or did not come up in time."""


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def build_environment(build_dir, master_port=None):
    """os.environ with the build's devel/setup.bash sourced, /usr/bin first on PATH (Debian's
    ROS tools need the system interpreter) and, with a port, a private master's URI."""
    setup = os.path.join(os.path.abspath(build_dir), "devel", "setup.bash")
    if not os.path.isfile(setup):
        raise SessionError("%s not found: build the package first (scripts/build, or set BUILD_DIR)" % setup)
    env = dict(os.environ, PATH="/usr/bin:" + os.environ.get("PATH", ""))
    dump = subprocess.run(["bash", "-c", 'source "%s" && env -0' % setup], stdout=subprocess.PIPE, env=env)
    if dump.returncode != 0:
        raise SessionError("sourcing %s failed" % setup)
    env = dict(kv.split("=", 1) for kv in dump.stdout.decode().split("\0") if "=" in kv)
    env["PATH"] = "/usr/bin:" + env.get("PATH", "")
    if master_port:
        env["ROS_MASTER_URI"] = "http://127.0.0.1:%d" % master_port
        env["ROS_HOSTNAME"] = "127.0.0.1"
        env.pop("ROS_IP", None)
    return env


def stop_process(process, timeout=15.0):
    """SIGINT to the process group (as Ctrl-C), then SIGTERM, then SIGKILL; never hangs. Returns
    the signal that stopped it (0: it had exited already)."""
    if process is None or process.poll() is not None:
        return 0
    for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 5), (signal.SIGKILL, 5)):
        try:
            os.killpg(process.pid, sig)
        except ProcessLookupError:
            return sig
        try:
            process.wait(wait)
            return sig
        except subprocess.TimeoutExpired:
            continue
    return signal.SIGKILL


def wait_for(predicate, timeout, what):
    """Polls `predicate` until it is true; SessionError naming `what` after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.2)
    raise SessionError("%s within %.0f s" % (what, timeout))


def cpu_seconds(pid):
    """utime + stime of a process [s], from /proc/<pid>/stat (fields 14 and 15)."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def children_cpu_seconds(pid):
    """cutime + cstime: CPU of the process's children that have exited and been waited for [s]."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[13]) + int(fields[14])) / os.sysconf("SC_CLK_TCK")


def rss_mb(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def percentile(values, q):
    """Nearest-rank percentile (q in [0, 100])."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    rank = max(1, int(-(-q * len(ordered) // 100)))
    return ordered[min(rank, len(ordered)) - 1]


class Ros:
    """A private master (roscore on a free port) and the environment for the ROS tools."""

    def __init__(self, build_dir, work_dir, debug_node_log=False):
        self.build_dir = build_dir
        self.port = free_port()
        self.env = build_environment(build_dir, self.port)
        if debug_node_log:  # per-keyframe insertion times are the node's debug lines
            config = os.path.join(work_dir, "rosconsole.config")
            with open(config, "w") as f:
                f.write("log4j.logger.ros=INFO\nlog4j.logger.ros.view_selection=DEBUG\n")
            self.env["ROSCONSOLE_CONFIG_FILE"] = config
        self.env["ROS_LOG_DIR"] = os.path.join(work_dir, "ros_log")
        self.master = subprocess.Popen(["roscore", "-p", str(self.port)], stdout=subprocess.DEVNULL,
                                       stderr=subprocess.DEVNULL, env=self.env, start_new_session=True)
        wait_for(lambda: self.call(["rosparam", "get", "/rosversion"], 5).returncode == 0, 30,
                 "the ROS master did not start")

    def call(self, cmd, timeout, **kw):
        """A command in the session's environment; exit 124 and what it printed on a timeout."""
        try:
            return subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=self.env,
                                  timeout=timeout, universal_newlines=True, **kw)
        except subprocess.TimeoutExpired as e:
            out = e.output.decode() if isinstance(e.output, bytes) else (e.output or "")
            return subprocess.CompletedProcess(cmd, 124, out)

    def tool(self, name):
        path = os.path.join(self.build_dir, "devel", "lib", "view_selection", name)
        if not os.access(path, os.X_OK):
            raise SessionError("%s is not built (no %s)" % (name, path))
        return path

    wait_for = staticmethod(wait_for)

    def node_pid(self, node):
        done = self.call(["rosnode", "info", node], 20)  # without -q: asks the node itself for its Pid
        match = re.search(r"Pid: (\d+)", done.stdout)
        return int(match.group(1)) if match else None

    def statistics_of(self, node):
        """The node's latched ~statistics as a dict (rostopic echo -n 1), or None."""
        import yaml
        done = self.call(["rostopic", "echo", "-n", "1", node + "/statistics"], 20)
        if done.returncode != 0:
            return None
        try:
            stats = yaml.safe_load(done.stdout.split("\n---")[0])
        except yaml.YAMLError:
            return None
        if not isinstance(stats, dict):
            return None
        stats["drops"] = dict(zip(stats.get("drop_reasons") or [], stats.get("drop_counts") or []))
        return stats

    def bag_counts(self, bag):
        """{topic: messages} of a bag (rosbag info --yaml)."""
        import yaml
        done = self.call(["rosbag", "info", "--yaml", "--key", "topics", bag], 120)
        try:
            topics = yaml.safe_load(done.stdout) or []
        except yaml.YAMLError:
            topics = []
        counts = {t["topic"]: int(t["messages"]) for t in topics if isinstance(t, dict) and "topic" in t}
        if not counts:
            raise SessionError("%s: no topics (rosbag info: %s)" % (bag, done.stdout.strip()[:400]))
        return counts

    def stop(self):
        stop_process(self.master, 10)
