"""Where a long-running Python process spends its time, for development: a thread that looks at
every other thread's stack a hundred times a second and counts, for each function, the samples
in which it was running or called what was running (inclusive), leaving out the samples in which
a thread only waited (a lock, a sleep, a socket). At exit the counts go to a file, the most first.

Started by colmap_bridge when VIEW_SELECTION_STACK_SAMPLES names that file (no profiler is
installed on the machines it runs on, and cProfile slows every call):

  VIEW_SELECTION_STACK_SAMPLES=/tmp/bridge_stacks.txt roslaunch view_selection tum_replay.launch ...
"""
import atexit
import collections
import os
import sys
import threading
import time

# A thread whose innermost frame is one of these is waiting, not working.
WAITING = {"wait", "sleep", "select", "poll", "accept", "recv", "recv_into", "readinto", "acquire", "_wait_for_tstate_lock",
           "get", "read", "readline", "serve_forever", "handle_request", "_recv_exact", "epoll"}


class StackSampler(threading.Thread):
    def __init__(self, path, period=0.01, depth=40):
        super().__init__(name="stack_sampler", daemon=True)
        self.path, self.period, self.depth = path, float(period), int(depth)
        self.inclusive = collections.Counter()  # "file:line function" -> samples
        self.innermost = collections.Counter()
        self.samples = 0
        self.stopping = False

    def run(self):
        me = threading.get_ident()
        while not self.stopping:
            for ident, frame in sys._current_frames().items():
                if ident == me or frame.f_code.co_name in WAITING:
                    continue
                self.samples += 1
                seen = set()
                self.innermost[self.label(frame)] += 1
                for _ in range(self.depth):
                    if frame is None:
                        break
                    label = self.label(frame)
                    if label not in seen:
                        seen.add(label)
                        self.inclusive[label] += 1
                    frame = frame.f_back
            time.sleep(self.period)

    @staticmethod
    def label(frame):
        code = frame.f_code
        return "%s:%d %s" % (os.path.basename(code.co_filename), code.co_firstlineno, code.co_name)

    def write(self):
        self.stopping = True
        lines = ["%d working samples (every %.0f ms): inclusive, then innermost" % (self.samples, 1000 * self.period)]
        for title, counts in (("inclusive", self.inclusive), ("innermost", self.innermost)):
            lines.append("-- %s" % title)
            for label, n in counts.most_common(60):
                lines.append("%7d %5.1f%%  %s" % (n, 100.0 * n / max(1, self.samples), label))
        with open(self.path, "w") as f:
            f.write("\n".join(lines) + "\n")


def start_from_environment():
    """A sampler writing to $VIEW_SELECTION_STACK_SAMPLES at exit, when it is set; else nothing."""
    path = os.environ.get("VIEW_SELECTION_STACK_SAMPLES")
    if not path:
        return None
    sampler = StackSampler(path)
    sampler.start()
    atexit.register(sampler.write)
    return sampler
