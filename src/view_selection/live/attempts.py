"""Items that failed (an image COLMAP could not extract, a pair it could not match), retried with
a growing wait a bounded number of times, then given up and reported. No ROS."""
import time


class Attempts:
    """Per item: failures so far, when it may be tried again, and the last error."""

    def __init__(self, max_attempts=3, first_wait=2.0, factor=4.0, clock=time.monotonic):
        self.max_attempts, self.first_wait, self.factor, self.clock = int(max_attempts), first_wait, factor, clock
        self.failures = {}   # item -> count
        self.not_before = {}  # item -> clock time
        self.errors = {}     # item -> last error text

    def failed(self, item, error):
        """Records a failure; True when the item is now given up."""
        n = self.failures.get(item, 0) + 1
        self.failures[item] = n
        self.errors[item] = str(error)
        self.not_before[item] = self.clock() + self.first_wait * self.factor ** (n - 1)
        return n >= self.max_attempts

    def succeeded(self, item):
        self.failures.pop(item, None)
        self.not_before.pop(item, None)
        self.errors.pop(item, None)

    def given_up(self, item):
        return self.failures.get(item, 0) >= self.max_attempts

    def suspect(self, item):
        """Failed before (so tried alone next time, not in a batch)."""
        return self.failures.get(item, 0) > 0

    def due(self, item):
        """Not given up and not waiting."""
        return not self.given_up(item) and self.clock() >= self.not_before.get(item, 0.0)

    def skipped(self, all_failed=False):
        """[{'item', 'attempts', 'error'}] of the items given up (all_failed: of every item that
        failed and has not succeeded since)."""
        return [{"item": item, "attempts": n, "error": self.errors.get(item, "")}
                for item, n in sorted(self.failures.items(), key=lambda kv: str(kv[0]))
                if all_failed or n >= self.max_attempts]
