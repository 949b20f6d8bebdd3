"""A consumer's copy of a view_selection node's pair stream (~pairs, ~get_pairs), without ROS.

The node numbers its PairChanges messages. A consumer applies them in sequence; a message that
skips one (a gap), or one from before (the node started over), means the consumer missed
something and must catch up through ~get_pairs(since = the last sequence applied), which answers
the messages after it or one `full` message with the whole announced set. Messages are duck-typed:
anything with the fields of view_selection/PairChanges works (tests pass plain objects).
"""
import time

from ..keyframes import Keyframe


class PairStream:
    """keyframes {id: Keyframe}, announced {(id, id)}, the last sequence applied, and whether a
    catch-up is due. Not thread-safe: the caller holds its own lock."""

    def __init__(self, clock=time.monotonic):
        self.clock = clock
        self.keyframes = {}
        self.announced = set()
        self.sequence = 0
        self.need_sync = True          # until the first ~get_pairs
        self.messages = 0              # applied
        self.pending_pairs = 0         # the node's selected pairs not announced yet
        self.last_keyframe_time = None  # when a keyframe new to us last came
        self.last_change_time = clock()

    def apply(self, msg):
        """Applies one message (in sequence, or `full`)."""
        if msg.full:
            self.announced = set()
            if msg.total_keyframes < len(self.keyframes):
                self.keyframes = {}  # a new session: fewer keyframes than we hold
        for k in msg.keyframes:
            kf = Keyframe.from_msg(k)
            if kf.id not in self.keyframes:
                self.last_keyframe_time = self.clock()
            self.keyframes[kf.id] = kf
        for p in msg.removed:
            self.announced.discard((p.first, p.second))
        for p in msg.added:
            self.announced.add((p.first, p.second))
        self.sequence = msg.sequence
        self.messages += 1
        self.pending_pairs = msg.pending_pairs
        self.last_change_time = self.clock()

    def receive(self, msg):
        """A message from ~pairs: applied when it is the next one (or full); True if applied.
        A gap or an earlier sequence sets need_sync instead."""
        if msg.full or msg.sequence == self.sequence + 1:
            self.apply(msg)
            return True
        if msg.sequence != self.sequence:  # a duplicate of the last one is harmless
            self.need_sync = True
        return False

    def catch_up(self, sequence, changes):
        """The answer of ~get_pairs(since=self.sequence): the node's current sequence and the
        messages after ours (or one full message)."""
        if sequence < self.sequence:
            self.sequence = 0  # the node restarted without its state: its whole set follows
        for m in changes:
            if m.full or m.sequence == self.sequence + 1:
                self.apply(m)
            elif m.sequence > self.sequence + 1:
                self.need_sync = True  # still a gap: ask again next time
                return
        self.need_sync = False

    def ordered_keyframes(self):
        return sorted(self.keyframes.values(), key=lambda k: k.id)

    def announced_names(self):
        """The announced pairs whose keyframes we know, as image names."""
        names = {k.id: k.name for k in self.keyframes.values()}
        return [(names[a], names[b]) for a, b in self.announced if a in names and b in names]
