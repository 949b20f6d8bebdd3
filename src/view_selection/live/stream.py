"""A consumer's copy of a view_selection node's pair stream (~pairs, ~get_pairs), without ROS.

The node numbers its PairChanges messages. A consumer applies them in sequence; a message that
skips one (a gap), or one from before (the node started over), means the consumer missed
something and must catch up through ~get_pairs(since = the last sequence applied), which answers
the messages after it or one `full` message with the whole announced set. Messages are duck-typed:
anything with the fields of view_selection/PairChanges works (tests pass plain objects).

The announced pairs go to the bridge's worker as what changed since it last took them
(take_changes), so that a batch's work on them is that of what changed, not of the session
(issue 34).
"""
import collections
import time

from ..keyframes import Keyframe, pair_of

AnnouncedChanges = collections.namedtuple("AnnouncedChanges", "added removed")
AnnouncedChanges.__doc__ = """The announced pairs (names, sorted within) that a consumer's copy of the
set gains and loses: `added` were not in it and are now, `removed` were and are not (a pair taken
back and announced again in between is in neither). Two sets."""


class NetChanges:
    """What a set gained and lost since the last take(), net: told each item that enters the set
    (added) and each that leaves it (removed), never one that was in it already or was not."""

    def __init__(self):
        self.added, self.removed = set(), set()

    def add(self, item):
        if item in self.removed:
            self.removed.discard(item)  # back where it was at the last take
        else:
            self.added.add(item)

    def remove(self, item):
        if item in self.added:
            self.added.discard(item)
        else:
            self.removed.add(item)

    def take(self):
        out = AnnouncedChanges(self.added, self.removed)
        self.added, self.removed = set(), set()
        return out


class PairStream:
    """keyframes {id: Keyframe}, announced {(id, id)}, the last sequence applied, and whether a
    catch-up is due. Not thread-safe: the caller holds its own lock."""

    def __init__(self, clock=time.monotonic):
        self.clock = clock
        self.keyframes = {}
        self.announced = set()
        # The announced pairs as image names (pair_of: sorted within), kept as messages come, so
        # that a batch does not convert the whole set again (issue 34); pairs whose keyframes are
        # not known yet wait in _unnamed (ids).
        self._named, self._unnamed = set(), set()
        self._changes = NetChanges()  # of _named, since take_changes()
        self.taken_back = []  # announced pairs (names) no longer announced, since take_taken_back()
        # The keyframes ordered by id, kept as they come (a batch does not sort the session again):
        # a new id beyond the last is appended, a known one replaced where it is; None when it must
        # be sorted again (an id that came before the last one).
        self._ordered, self._position = [], {}
        self.sequence = 0
        self.need_sync = True          # until the first ~get_pairs
        self.messages = 0              # applied
        self.pending_pairs = 0         # the node's selected pairs not announced yet
        self.last_keyframe_time = None  # when a keyframe new to us last came
        self.last_change_time = clock()
        # The node's `flushed` messages: no frame reached it for ~pair_flush_idle (the recording
        # paused or ended). Keyframes alone pause whenever the camera walks where it has been.
        self.last_pause_time = None     # when the last one came
        self.pauses_told = False        # this node tells its pauses (every pause, since issue 34)

    def apply(self, msg):
        """Applies one message (in sequence, or `full`)."""
        full = msg.full
        if full:
            before = self._named  # what a full message does not hold is taken back
            self.announced = set()
            self._named, self._unnamed = set(), set()
            if msg.total_keyframes < len(self.keyframes):
                self.keyframes = {}  # a new session: fewer keyframes than we hold
                self._ordered, self._position = [], {}
        new = []
        for k in msg.keyframes:
            kf = Keyframe.from_msg(k)
            if kf.id not in self.keyframes:
                self.last_keyframe_time = self.clock()
                new.append(kf.id)
            self._keep(kf)
        if new and self._unnamed:
            for pair in [p for p in self._unnamed if p[0] in self.keyframes and p[1] in self.keyframes]:
                self._unnamed.discard(pair)
                self._announce(self._name_of(pair), full)
        for p in msg.removed:
            pair = (p.first, p.second)
            self.announced.discard(pair)
            self._unnamed.discard(pair)
            if p.first in self.keyframes and p.second in self.keyframes:
                name = self._name_of(pair)
                if name in self._named:
                    self._named.discard(name)
                    self.taken_back.append(name)
                    if not full:
                        self._changes.remove(name)
        for p in msg.added:
            pair = (p.first, p.second)
            self.announced.add(pair)
            if p.first in self.keyframes and p.second in self.keyframes:
                self._announce(self._name_of(pair), full)
            else:
                self._unnamed.add(pair)
        if full:
            # The changes against the set before it (the whole set compared: full messages are
            # rare, a catch-up or a new session).
            gone = before - self._named
            self.taken_back.extend(sorted(gone))
            for name in gone:
                self._changes.remove(name)
            for name in self._named - before:
                self._changes.add(name)
        self.sequence = msg.sequence
        self.messages += 1
        self.pending_pairs = msg.pending_pairs
        if getattr(msg, "flushed", False):
            self.last_pause_time = self.clock()
            self.pauses_told = True
        if msg.full or msg.keyframes or msg.added or msg.removed:  # a pause alone changes nothing
            self.last_change_time = self.clock()

    def frames_paused(self):
        """True when the node said its frames stopped after the last keyframe new to us."""
        return self.last_pause_time is not None and (self.last_keyframe_time is None
                                                     or self.last_pause_time >= self.last_keyframe_time)

    def quiet(self, seconds):
        """Whether the session may be about to end, so that what waits is best done now: no
        keyframe new to us for `seconds`, or the node said its frames stopped (its `flushed`
        message, at its ~pair_flush_idle, which may come sooner)."""
        return self.until_idle(seconds) == 0 or self.frames_paused()

    def until_idle(self, seconds):
        """How long until no keyframe new to us has come for `seconds` (0 once it has; None
        without keyframes): the bridge waits no longer than that to see whether its finish is
        due, so that it begins when it is, not up to a batch period later."""
        if self.last_keyframe_time is None:
            return None
        return max(0.0, self.last_keyframe_time + seconds - self.clock())

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

    def _keep(self, kf):
        known = kf.id in self.keyframes
        self.keyframes[kf.id] = kf
        if self._ordered is None:
            return
        if known:
            self._ordered[self._position[kf.id]] = kf
        elif not self._ordered or kf.id > self._ordered[-1].id:
            self._position[kf.id] = len(self._ordered)
            self._ordered.append(kf)
        else:
            self._ordered = None

    def ordered_keyframes(self):
        """The keyframes by id, a list of its own."""
        if self._ordered is None:
            self._ordered = sorted(self.keyframes.values(), key=lambda k: k.id)
            self._position = {k.id: i for i, k in enumerate(self._ordered)}
        return list(self._ordered)

    def _name_of(self, pair):
        return pair_of(self.keyframes[pair[0]].name, self.keyframes[pair[1]].name)

    def _announce(self, name, full):
        """A pair announced under its names (a full message's changes are found at its end)."""
        if name not in self._named:
            self._named.add(name)
            if not full:
                self._changes.add(name)

    def take_taken_back(self):
        """The pairs (names) taken back since the last call, in the order they were."""
        out, self.taken_back = self.taken_back, []
        return out

    def take_changes(self):
        """AnnouncedChanges: how the announced pairs whose keyframes we know (names, sorted
        within) changed since the last call (the first call: every one of them). A consumer that
        applies each in turn to a set that began empty holds announced_names()."""
        return self._changes.take()

    def announced_names(self):
        """The announced pairs whose keyframes we know, as image names (sorted within), a set of
        its own (the caller may keep it outside the lock). A copy of the whole set: for a finish,
        not for every batch (take_changes)."""
        return set(self._named)
