"""Progress of long work, as COLMAP's own tools report theirs: the stage, the count done of the
total and an estimate of the time left ("matching 1200/2885 pairs, about 40 s left").

On a terminal (the stream is a tty) one line is rewritten in place (\\r), at most a few times a
second; into a log or a pipe a plain line at most every `interval` seconds (10), so that a log
of an hour's work stays readable. A stage that ends before anything was shown shows nothing:
short work stays silent. The C++ tools use the same rules (include/view_selection/io/progress.h).

The estimate is the stage's mean rate so far: elapsed / done x (total - done). The clock is
injected (a function returning seconds, time.monotonic by default), so the rules are tested
without sleeping.
"""
import math
import sys
import time

# [s] between two plain lines (a log or a pipe), and between two redraws on a terminal.
LOG_INTERVAL = 10.0
TERMINAL_INTERVAL = 0.25


def duration_text(seconds):
    """'40 s', '12 min', '2.5 h': as precise as an estimate deserves."""
    half_up = lambda x: int(math.floor(x + 0.5))  # as C++'s lround, not Python's half-to-even
    if seconds < 90:
        return "%d s" % max(1, half_up(seconds))
    if seconds < 90 * 60:
        return "%d min" % half_up(seconds / 60.0)
    return "%.1f h" % (seconds / 3600.0)


class Progress:
    """One reporter for a tool's long work. `report(stage, done, total, unit)` as the work goes
    (a new stage name starts a new estimate), `end()` after the stage's last item (its final
    line, when anything of it was shown), `note(text)` for a line from elsewhere (a child
    process's own progress), `clear()` before the tool prints something else on the stream."""

    def __init__(self, stream=None, terminal=None, clock=time.monotonic, interval=LOG_INTERVAL,
                 redraw=TERMINAL_INTERVAL):
        self.stream = stream if stream is not None else sys.stderr
        if terminal is None:
            try:
                terminal = self.stream.isatty()
            except (AttributeError, ValueError):
                terminal = False
        self.terminal, self.clock = bool(terminal), clock
        self.interval, self.redraw = float(interval), float(redraw)
        self.stage, self.unit, self.done, self.total = None, "", 0, 0
        self.shown_complete = False  # the last line shown had the stage's whole count
        self.started = None       # when the stage started
        self.shown_at = None      # when a line was last shown (any stage), None: never
        self.stage_shown = False  # a line of this stage was shown
        self.on_line = False      # a terminal line is drawn and not ended

    # -- what the line says ------------------------------------------------------------------
    def line(self, now=None, final=False):
        """'matching 1200/2885 pairs, about 40 s left' for the stage as it is; `final`, or with
        the whole count: the time it took instead ('matching 1/4 rounds, 43 s': it ended early)."""
        now = self.clock() if now is None else now
        text = "%s %d/%d%s" % (self.stage, self.done, self.total, " " + self.unit if self.unit else "")
        left = self.estimate(now)
        if final or self.done >= self.total:
            text += ", %s" % duration_text(now - self.started)
        elif left is not None:
            text += ", about %s left" % duration_text(left)
        return text

    def estimate(self, now=None):
        """Seconds left at the stage's mean rate so far; None before the first item is done."""
        now = self.clock() if now is None else now
        if self.started is None or self.done <= 0 or self.done >= self.total:
            return None
        return (now - self.started) / self.done * (self.total - self.done)

    # -- reporting ---------------------------------------------------------------------------
    def report(self, stage, done, total, unit=""):
        """The work so far. A new stage name, or a count that went back (the same work run again
        on another batch), starts a new estimate. The stage's whole count shows its last line at
        once (when anything of it was shown)."""
        now = self.clock()
        if stage != self.stage or done < self.done:
            self.end()
            self.stage, self.unit, self.started, self.stage_shown = stage, unit, now, False
            self.shown_complete = False
        self.done, self.total = int(done), max(int(total), int(done))
        complete = self.done >= self.total
        if self._due(now) or (complete and self.stage_shown and not self.shown_complete):
            self._show(self.line(now), now)
            self.shown_complete = complete

    def note(self, text):
        """A line from elsewhere (e.g. refine_model's own progress), under the same rules; it
        ends the stage under way and starts one of its own, which ends without a line."""
        now = self.clock()
        if self.stage:
            self.end()
        if self.stage is None:
            self.stage, self.unit, self.started, self.stage_shown, self.total = "", "", now, False, 0
        if self._due(now):
            self._show(text, now)
            self.shown_complete = False

    def end(self):
        """The stage's last line, when the stage was shown at all (and its last line was not the
        complete count already): how far it got and the time it took; then a new line."""
        if self.stage and self.stage_shown and not self.shown_complete:
            self._show(self.line(final=True), self.clock())
        self.clear()
        self.stage, self.stage_shown = None, False

    def clear(self):
        """Ends the line drawn in place, so that what is printed next starts on its own."""
        if self.on_line:
            self.stream.write("\n")
            self.stream.flush()
            self.on_line = False

    def _due(self, now):
        """A stage shows itself once it has run a second on a terminal, `interval` in a log (short
        work prints nothing); then at most every `redraw`, or every `interval`, seconds."""
        since_start = now - self.started
        since_shown = None if self.shown_at is None else now - self.shown_at
        if self.terminal:
            return since_start >= 1.0 and (since_shown is None or since_shown >= self.redraw)
        return since_start >= self.interval and (since_shown is None or since_shown >= self.interval)

    def _show(self, text, now):
        if self.terminal:
            self.stream.write("\r" + text + "\033[K")
            self.on_line = True
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self.shown_at, self.stage_shown = now, True
