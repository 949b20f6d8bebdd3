"""Items that failed (an image COLMAP could not extract, a pair it could not match), retried with
a growing wait a bounded number of times, then given up and reported; and items suspected
without a failure charged (they were in a run that hung: one of them, or none, is the culprit),
tried alone next. No ROS."""
import time


class Attempts:
    """Per item: failures so far, when it may be tried again, and the last error."""

    def __init__(self, max_attempts=3, first_wait=2.0, factor=4.0, clock=time.monotonic):
        self.max_attempts, self.first_wait, self.factor, self.clock = int(max_attempts), first_wait, factor, clock
        self.failures = {}   # item -> count
        self.not_before = {}  # item -> clock time
        self.errors = {}     # item -> last error text
        self.suspects = set()  # items in a run that timed out, not charged: tried alone next
        self._given_up = 0     # how many items are given up now (kept as it changes: the diagnostics ask)

    def failed(self, item, error):
        """Records a failure; True when the item is now given up."""
        n = self.failures.get(item, 0) + 1
        self.failures[item] = n
        self.errors[item] = str(error)
        self.not_before[item] = self.clock() + self.first_wait * self.factor ** (n - 1)
        if n == self.max_attempts:
            self._given_up += 1
        return n >= self.max_attempts

    def given_up_before(self, item, error):
        """The item was given up in an earlier run (a bridge killed and started again on its
        project): one more try, not ~max_attempts; a failure gives it up again at once."""
        if self.failures.get(item, 0) < self.max_attempts - 1:  # (with max_attempts 1: a try as any)
            self.failures[item] = self.max_attempts - 1
            self.errors[item] = str(error)

    def suspected(self, item):
        """The item was in a run of several that timed out: it is tried alone next, and only a
        failure alone is charged (so a hang costs only the item that hangs)."""
        self.suspects.add(item)

    def succeeded(self, item):
        self.suspects.discard(item)
        if self.given_up(item):
            self._given_up -= 1
        self.failures.pop(item, None)
        self.not_before.pop(item, None)
        self.errors.pop(item, None)

    def given_up(self, item):
        return self.failures.get(item, 0) >= self.max_attempts

    def suspect(self, item):
        """Failed before, or was in a run that hung (so tried alone next time, not in a batch)."""
        return item in self.suspects or self.failures.get(item, 0) > 0

    def given_up_count(self):
        """len(skipped()), without looking at each item."""
        return self._given_up

    def due(self, item):
        """Not given up and not waiting."""
        return not self.given_up(item) and self.clock() >= self.not_before.get(item, 0.0)

    def skipped(self, all_failed=False):
        """[{'item', 'attempts', 'error'}] of the items given up (all_failed: of every item that
        failed and has not succeeded since)."""
        return [{"item": item, "attempts": n, "error": self.errors.get(item, "")}
                for item, n in sorted(self.failures.items(), key=lambda kv: str(kv[0]))
                if all_failed or n >= self.max_attempts]
