"""The pair stream's consumer: in-order application, gaps, catch-up, restarts of the node, and
the changes of the announced pairs handed to the bridge's worker (take_changes)."""
import random
from types import SimpleNamespace as NS

from view_selection.live.stream import PairStream


def keyframe(i, session="", x=None):
    pose = NS(position=NS(x=float(i if x is None else x), y=0.0, z=0.0), orientation=NS(w=1.0, x=0.0, y=0.0, z=0.0))
    return NS(id=i, image_name="%s%d.png" % (session, i), stamp=NS(to_sec=lambda i=i: 100.0 + i), pose=pose,
              intrinsics=[500.0, 500.0, 320.0, 240.0], width=640, height=480)


def msg(seq, added=(), removed=(), keyframes=(), full=False, total=None, pending=0, flushed=False):
    return NS(sequence=seq, full=full, flushed=flushed, added=[NS(first=a, second=b) for a, b in added],
              removed=[NS(first=a, second=b) for a, b in removed],
              keyframes=[keyframe(k) if isinstance(k, int) else k for k in keyframes],
              total_keyframes=total if total is not None else len(keyframes), pending_pairs=pending)


def test_messages_in_sequence_are_applied():
    s = PairStream()
    assert s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    assert s.receive(msg(2, added=[(1, 2), (0, 2)], keyframes=[2], total=3))
    assert s.receive(msg(3, removed=[(0, 2)], total=3, pending=4))
    assert s.sequence == 3 and s.announced == {(0, 1), (1, 2)} and s.pending_pairs == 4
    assert sorted(s.announced_names()) == [("0.png", "1.png"), ("1.png", "2.png")]
    assert [k.id for k in s.ordered_keyframes()] == [0, 1, 2]


def test_a_gap_asks_for_a_catch_up_and_applies_nothing():
    s = PairStream()
    s.catch_up(0, [])
    assert not s.need_sync
    s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    assert not s.receive(msg(3, added=[(5, 6)], keyframes=[5, 6]))  # 2 was missed
    assert s.need_sync and s.sequence == 1 and s.announced == {(0, 1)}


def test_a_duplicate_is_harmless():
    s = PairStream()
    s.catch_up(0, [])
    s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    assert not s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    assert not s.need_sync


def test_catch_up_applies_the_missed_messages_in_order():
    s = PairStream()
    s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    s.receive(msg(3, added=[(2, 3)], keyframes=[2, 3]))
    s.catch_up(3, [msg(2, added=[(1, 2)], keyframes=[2], total=3),
                   msg(3, added=[(2, 3)], removed=[(0, 1)], keyframes=[3], total=4)])
    assert s.sequence == 3 and not s.need_sync
    assert s.announced == {(1, 2), (2, 3)}


def test_a_full_message_replaces_the_announced_set():
    s = PairStream()
    s.receive(msg(1, added=[(0, 1), (1, 2)], keyframes=[0, 1, 2]))
    s.catch_up(9, [msg(9, added=[(1, 2)], full=True, total=3)])
    assert s.sequence == 9 and s.announced == {(1, 2)} and len(s.keyframes) == 3


def test_a_node_restarted_without_state_starts_the_consumer_over():
    s = PairStream()
    s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    s.receive(msg(2, added=[(1, 2)], keyframes=[2], total=3))
    # a new session: sequence 1 again, with fewer keyframes than the consumer holds
    s.catch_up(1, [msg(1, added=[(0, 1)], keyframes=[0, 1], full=True, total=2)])
    assert s.sequence == 1 and s.announced == {(0, 1)} and sorted(s.keyframes) == [0, 1]


def test_a_gap_inside_the_answer_asks_again():
    s = PairStream()
    s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    s.catch_up(4, [msg(3, added=[(1, 2)], keyframes=[2], total=3)])
    assert s.need_sync and s.sequence == 1


def test_new_keyframes_are_timed_by_the_clock():
    now = [10.0]
    s = PairStream(clock=lambda: now[0])
    s.receive(msg(1, keyframes=[0]))
    now[0] = 12.0
    s.receive(msg(2, keyframes=[0], total=1))  # the same keyframe again (a pose update)
    assert s.last_keyframe_time == 10.0 and s.last_change_time == 12.0


def test_the_time_until_the_keyframes_have_paused_long_enough():
    # colmap_bridge looks again whether its finish is due when ~finish_after_idle has passed
    # since the last keyframe, not a batch period after the node's flushed message woke it.
    now = [10.0]
    s = PairStream(clock=lambda: now[0])
    assert s.until_idle(1.0) is None  # no keyframe yet: nothing to wait for
    s.receive(msg(1, keyframes=[0]))
    now[0] = 10.5
    assert s.until_idle(1.0) == 0.5
    s.receive(msg(2, keyframes=[0], total=1))  # a pose update is not a new keyframe
    assert s.until_idle(1.0) == 0.5
    s.receive(msg(3, keyframes=[0, 1], total=2))
    assert s.until_idle(1.0) == 1.0
    now[0] = 12.0
    assert s.until_idle(1.0) == 0.0


def test_quiet_once_keyframes_paused_or_the_node_said_its_frames_stopped():
    # colmap_bridge matches what waits when quiet, so that the finish does not have to.
    now = [10.0]
    s = PairStream(clock=lambda: now[0])
    assert not s.quiet(0.5)  # no keyframe yet
    s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    now[0] = 10.4
    assert not s.quiet(0.5)
    now[0] = 10.5
    assert s.quiet(0.5)
    s.receive(msg(2, keyframes=[2], added=[(1, 2)], total=3))  # the walk goes on
    assert not s.quiet(0.5)
    now[0] = 10.6
    s.receive(msg(3, total=3, flushed=True))  # the node's frames stopped, before the idle time
    assert s.quiet(0.5)
    now[0] = 10.7
    s.receive(msg(4, keyframes=[3], total=4))  # and came again
    assert not s.quiet(0.5)


def test_the_node_s_pauses_are_told_apart_from_pauses_of_keyframes():
    # colmap_bridge finishes once the node says its frames stopped (a flushed message), not
    # whenever keyframes pause: walking where the camera has been makes none.
    now = [10.0]
    s = PairStream(clock=lambda: now[0])
    s.receive(msg(1, added=[(0, 1)], keyframes=[0, 1]))
    assert not s.pauses_told and not s.frames_paused()
    now[0] = 11.0
    s.receive(msg(2, total=2, flushed=True))  # nothing pending: the pause alone
    assert s.pauses_told and s.frames_paused()
    assert s.last_change_time == 10.0  # a pause alone changes nothing: no second finish for it
    now[0] = 20.0
    s.receive(msg(3, keyframes=[2], added=[(1, 2)], total=3))  # frames came again, and a keyframe
    assert not s.frames_paused()
    now[0] = 21.0
    s.receive(msg(4, added=[(0, 2)], keyframes=[0, 2], total=3, flushed=True))  # pairs flushed at a pause
    assert s.frames_paused() and s.last_change_time == 21.0
    now[0] = 22.0
    s.receive(msg(5, keyframes=[3], total=4))  # a keyframe after the pause
    assert not s.frames_paused()
    t = PairStream(clock=lambda: now[0])
    t.catch_up(5, [msg(5, added=[(0, 1)], keyframes=[0, 1, 2, 3], full=True, flushed=True)])
    assert t.frames_paused()  # a bridge that joins after the recording ended


def test_the_names_follow_every_change_as_a_full_conversion_would():
    # The names are kept as messages come (issue 34: no conversion of the whole set per batch);
    # after each message they must equal what the announced ids and known keyframes give.
    def converted(s):
        names = {k.id: k.name for k in s.keyframes.values()}
        return {tuple(sorted((names[a], names[b]))) for a, b in s.announced if a in names and b in names}
    s = PairStream()
    steps = [msg(1, added=[(0, 1), (1, 3)], keyframes=[0, 1]),      # (1, 3) before keyframe 3 is known
             msg(2, added=[(2, 0)], keyframes=[2, 3], total=4),      # 3 comes: (1, 3) gets its names
             msg(3, removed=[(0, 1)], added=[(4, 2)], total=4),      # (4, 2): 4 not known yet
             msg(4, removed=[(4, 2)], keyframes=[4], total=5),       # removed before its names came
             msg(5, added=[(3, 4)], full=True, keyframes=[0, 1, 2, 3, 4], total=5)]
    for m in steps:
        assert s.receive(m)
        assert s.announced_names() == converted(s), m.sequence
    assert s.announced_names() == {("3.png", "4.png")}


def test_pairs_taken_back_are_handed_over_once():
    s = PairStream()
    s.receive(msg(1, added=[(0, 1), (1, 2), (0, 2)], keyframes=[0, 1, 2]))
    s.receive(msg(2, removed=[(0, 2), (5, 6)], total=3))  # (5, 6) was never announced
    assert s.take_taken_back() == [("0.png", "2.png")]
    assert s.take_taken_back() == []
    s.receive(msg(3, added=[(2, 3)], keyframes=[3], total=4))
    s.receive(msg(4, added=[(0, 1), (2, 3)], keyframes=[0, 1, 2, 3], full=True))  # (1, 2) is not in it
    assert s.take_taken_back() == [("1.png", "2.png")]
    assert s.announced_names() == {("0.png", "1.png"), ("2.png", "3.png")}


def names(*pairs):
    return {("%d.png" % a, "%d.png" % b) for a, b in pairs}


def test_a_pair_taken_back_and_announced_again_between_two_takes_is_no_change():
    s = PairStream()
    s.apply(msg(1, added=[(0, 1), (1, 2)], keyframes=[0, 1, 2]))
    assert s.take_changes() == (names((0, 1), (1, 2)), set())
    s.apply(msg(2, removed=[(0, 1)], total=3))
    s.apply(msg(3, added=[(0, 1), (0, 2)], total=3))  # (0, 1) back again; (0, 2) new
    s.apply(msg(4, removed=[(0, 2)], total=3))         # and (0, 2) gone before anyone took it
    assert s.take_changes() == (set(), set())
    s.apply(msg(5, removed=[(1, 2)], total=3))
    assert s.take_changes() == (set(), names((1, 2)))
    assert s.take_changes() == (set(), set())
    # The taken-back pairs for the ledger are every take-back, as before.
    assert s.take_taken_back() == sorted(names((0, 1))) + sorted(names((0, 2))) + sorted(names((1, 2)))


def test_a_full_message_gives_the_changes_against_the_set_before_it():
    s = PairStream()
    s.apply(msg(1, added=[(0, 1), (1, 2), (2, 3)], keyframes=[0, 1, 2, 3]))
    s.take_changes()
    s.apply(msg(2, removed=[(2, 3)], added=[(0, 3)], total=4))  # not taken yet when the full one comes
    s.apply(msg(9, added=[(1, 2), (2, 3), (0, 2)], keyframes=[0, 1, 2, 3], full=True))
    assert s.take_changes() == (names((0, 2)), names((0, 1)))  # (2, 3) went and came back
    # A new session: fewer keyframes, other images; every pair of the old one goes.
    s.apply(msg(1, added=[(0, 1)], keyframes=[keyframe(0, "b"), keyframe(1, "b")], full=True, total=2))
    assert s.take_changes() == ({("b0.png", "b1.png")}, names((1, 2), (2, 3), (0, 2)))


def test_the_changes_taken_follow_the_announced_names_through_every_kind_of_message():
    rng = random.Random(11)
    s = PairStream()
    mine = set()  # the consumer's copy, changed only by what it takes
    seq, known, session = 0, 0, ""
    for step in range(400):
        seq += 1
        if rng.random() < 0.04:  # a catch-up's full message (sometimes a new session: fewer keyframes)
            if rng.random() < 0.5:
                session, known = "s%d" % step, rng.randint(0, 5)
            total = known
            ids = list(range(total))
            pairs = {tuple(sorted(rng.sample(range(total + 3), 2))) for _ in range(rng.randint(0, 2 * total + 1))}
            s.apply(msg(seq, added=pairs, keyframes=[keyframe(i, session) for i in ids], full=True, total=total))
        else:
            new = list(range(known, known + rng.randint(0, 3)))
            moved = [rng.randrange(known)] if known and rng.random() < 0.3 else []
            known += len(new)
            # pairs of known keyframes, of keyframes not known yet (named when they come), and
            # pairs taken back (some announced, some never announced)
            added = [tuple(sorted(rng.sample(range(known + 3), 2))) for _ in range(rng.randint(0, 4))]
            removed = [tuple(sorted(rng.sample(range(known + 3), 2))) for _ in range(rng.randint(0, 3))]
            removed += rng.sample(sorted(s.announced), min(len(s.announced), rng.randint(0, 2)))
            s.apply(msg(seq, added=added, removed=removed, total=known,
                        keyframes=[keyframe(i, session, x=rng.random() if i in moved else None) for i in moved + new]))
        if rng.random() < 0.5:
            changes = s.take_changes()
            assert not (changes.added & mine) and changes.removed <= mine, step
            mine = (mine - changes.removed) | changes.added
            assert mine == s.announced_names(), step
