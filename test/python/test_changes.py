"""A batch's view of the session's keyframes: what changed since the last batch (live/changes.py),
the continuity chain kept as keyframes come (keyframes.ContinuityChain), and the stream's
keyframes kept in id order (PairStream.ordered_keyframes), each held against the whole-list
computation it replaces."""
import random
from types import SimpleNamespace as NS

from view_selection.keyframes import ContinuityChain, Keyframe, continuity_pairs
from view_selection.live.changes import KeyframeChanges
from view_selection.live.stream import PairStream


def kf(i, x=None, name=None):
    return Keyframe(i, name or "%04d.png" % i, i, (float(i if x is None else x), 0, 0), (1, 0, 0, 0),
                    (500, 500, 320, 240), 640, 480)


def test_appended_and_replaced_keyframes_are_what_changed():
    scan = KeyframeChanges()
    first = [kf(i) for i in range(5)]
    c = scan.scan(first)
    assert c.keyframes == first and c.new == first and not c.reset
    assert scan.scan(first) == ([], [], False)  # the same objects: nothing changed
    moved = kf(2, x=7.0)
    second = first[:2] + [moved] + first[3:] + [kf(5), kf(6)]
    c = scan.scan(second)
    assert c.keyframes == [moved, second[5], second[6]] and c.new == second[5:] and not c.reset


def test_a_shorter_list_or_another_image_in_a_place_is_a_reset():
    scan = KeyframeChanges()
    scan.scan([kf(i) for i in range(5)])
    shorter = [kf(i) for i in range(3)]
    assert scan.scan(shorter) == (shorter, shorter, True)
    other = shorter[:1] + [kf(1, name="other.png")] + shorter[2:] + [kf(3)]
    assert scan.scan(other) == (other, other, True)
    scan.forget()
    c = scan.scan(other)
    assert c.keyframes == other and not c.reset


def test_the_list_given_is_not_kept_itself():
    scan = KeyframeChanges()
    mine = [kf(0), kf(1)]
    scan.scan(mine)
    mine.append(kf(2))  # the caller's list grows afterwards: the scan saw two keyframes
    assert scan.scan(mine).new == [mine[2]]


def test_the_chain_kept_as_keyframes_come_is_the_chain_of_all_of_them():
    rng = random.Random(3)
    chain, have, next_id = ContinuityChain(), [], 0
    for step in range(300):
        new = []
        for _ in range(rng.randint(0, 4)):
            if rng.random() < 0.1 and next_id > 2:
                i = rng.randrange(next_id) + 0.5  # an id between two earlier ones: out of order
                new.append(kf(int(i * 10) + 100000, name="late%d_%d.png" % (step, len(new))))
            else:
                new.append(kf(next_id))
                next_id += 1
        have += new
        if chain.extend(new) is None:
            chain.rebuild(have)
        assert chain.pairs == set(continuity_pairs(have)), step


def test_extend_refuses_a_keyframe_before_the_last_and_changes_nothing():
    chain = ContinuityChain()
    assert chain.extend([kf(0), kf(1)]) == [("0000.png", "0001.png")]
    assert chain.extend([]) == []  # nothing new: nothing added, nothing refused
    before = set(chain.pairs)
    assert chain.extend([kf(3), kf(2)]) is None
    assert chain.pairs == before and chain.last.id == 1


def info(i, x=None):
    pose = NS(position=NS(x=float(i if x is None else x), y=0.0, z=0.0), orientation=NS(w=1.0, x=0.0, y=0.0, z=0.0))
    return NS(id=i, image_name="%d.png" % i, stamp=NS(to_sec=lambda i=i: 100.0 + i), pose=pose,
              intrinsics=[500.0, 500.0, 320.0, 240.0], width=640, height=480)


def msg(seq, keyframes, total, full=False):
    return NS(sequence=seq, full=full, flushed=False, added=[], removed=[], keyframes=keyframes,
              total_keyframes=total, pending_pairs=0)


def test_the_stream_keeps_its_keyframes_in_id_order_as_they_come():
    s = PairStream()
    s.apply(msg(1, [info(0), info(1), info(2)], 3))
    s.apply(msg(2, [info(5)], 4))
    s.apply(msg(3, [info(3)], 5))  # before the last: sorted again
    s.apply(msg(4, [info(1, x=9.0), info(6)], 6))  # a moved keyframe, and a new one
    ordered = s.ordered_keyframes()
    assert [k.id for k in ordered] == [0, 1, 2, 3, 5, 6]
    assert ordered[1].position[0] == 9.0 and ordered[1] is s.keyframes[1]
    assert ordered == sorted(s.keyframes.values(), key=lambda k: k.id)
    ordered.clear()  # a list of the caller's own
    assert len(s.ordered_keyframes()) == 6
    s.apply(msg(5, [info(0), info(1)], 2, full=True))  # a new session: fewer keyframes
    assert [k.id for k in s.ordered_keyframes()] == [0, 1]
