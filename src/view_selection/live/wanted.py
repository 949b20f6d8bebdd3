"""The pairs the bridge's worker wants matched, and of them the backlog: those not matched yet,
kept up to date from what changed (issue 34: a batch's work is the work of what changed, not
of the session; at 10,000 keyframes the set arithmetic over the whole session's pairs was
~5.7 ms of a 20 ms batch).

Wanted: the announced pairs (the node's, given whole or as their changes: stream.AnnouncedChanges)
and, beside them, the continuity chain's and the loop candidates' (looked up where they are kept:
`beside`). The backlog holds every wanted pair not known to be matched when it came. A pair
matched since (by a batch, by a run of COLMAP's matcher, or in an earlier run of the bridge on
the same project) leaves it when a batch next goes through the backlog (`waiting`): a batch's
bookkeeping costs the changes and the backlog, never the whole session. Pairs are names, sorted
within (keyframes.pair_of).
"""
from ..keyframes import pair_of
from .stream import AnnouncedChanges


class WantedPairs:
    def __init__(self, beside=lambda pair: False):
        """beside(pair): whether the pair is wanted besides being announced (continuity, loops)."""
        self.announced = set()
        self.backlog = set()
        self.beside = beside

    def __contains__(self, pair):
        return pair in self.announced or self.beside(pair)

    def apply(self, changes):
        """The announced pairs changed (anything with the sets `added` and `removed`, as
        stream.AnnouncedChanges: against what this holds). A pair taken back leaves the backlog
        unless it is wanted beside."""
        announced, backlog = self.announced, self.backlog
        for pair in changes.removed:
            announced.discard(pair)
            if not self.beside(pair):
                backlog.discard(pair)
        announced.update(changes.added)
        backlog.update(changes.added)

    def replace(self, pairs):
        """The announced pairs are exactly `pairs` now (any iterable of name pairs; a set or
        frozenset is taken as it is, its pairs sorted within, as PairStream gives them): the
        whole set compared with the one held, once (a caller that has the changes gives them
        to apply() instead)."""
        if isinstance(pairs, (set, frozenset)):
            new = pairs
        else:
            new = {pair_of(a, b) for a, b in pairs}
        self.apply(AnnouncedChanges(added=new - self.announced, removed=self.announced - new))

    def want(self, pairs):
        """Pairs wanted beside the announced ones since the last call (new continuity or loop
        pairs): they join the backlog."""
        self.backlog.update(pairs)

    def rebuild(self, beside):
        """The backlog again from everything wanted: the announced pairs and `beside` (the sets
        of pairs wanted beside them, whole), after the chain was built again (another session)
        or after a batch failed while it brought the pairs beside up to date."""
        self.backlog = self.everything(beside)

    def waiting(self, matched):
        """The backlog, sorted (oldest first by name); what `matched` holds leaves it first.
        The set is made anew: one that shrank keeps its table, and going through it costs the
        largest it ever was (a restarted bridge's 30,000 pairs matched: 0.3 ms a batch for 9)."""
        self.backlog = {pair for pair in self.backlog if pair not in matched}
        return sorted(self.backlog)

    def everything(self, beside):
        """Every wanted pair, a set of its own: the announced ones and `beside` (whole sets).
        The whole session: for a caller that asks, never for a batch."""
        out = set(self.announced)
        for pairs in beside:
            out |= pairs
        return out
