"""Pairs across revisits the poses do not show (matching/loops.py), and their place among the
work's wanted pairs."""
import math

import numpy as np
import pytest

from view_selection import geometry
from view_selection.keyframes import Keyframe, pair_of
from view_selection.live.work import LiveWork
from view_selection.matching.loops import LoopCandidates, LoopOptions

from test_work import FailingProject


def facing(yaw_deg):
    """Camera-to-world (w, x, y, z) of a camera looking along the world's x axis turned by yaw
    about z (camera axes: x right, y down, z the optical axis)."""
    y = math.radians(yaw_deg)
    forward = np.array([math.cos(y), math.sin(y), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    return geometry.quaternion_of(np.array([np.cross(down, forward), down, forward]).T)


def lap(start_id, laps=1, per_lap=80, radius=2.0, drift=(0.0, 0.0, 0.0), yaw_offset=0.0):
    """Keyframes on a circle of `radius` m, looking outwards, one every 360/per_lap degrees; each
    keyframe's position drifted by `drift` x (its index from start_id) / per_lap."""
    out = []
    for n in range(laps * per_lap):
        a = 2 * math.pi * n / per_lap
        k = start_id + n
        d = tuple(v * (n / per_lap) for v in drift)
        out.append(Keyframe(k, "%04d.png" % k, k, (radius * math.cos(a) + d[0], radius * math.sin(a) + d[1], d[2]),
                            facing(math.degrees(a) + yaw_offset), (500, 500, 320, 240), 640, 480))
    return out


def proposals_by_keyframe(pairs, kfs):
    """[(earlier id, later id)], by the later one."""
    index = {k.name: k.id for k in kfs}
    return sorted(((index[a], index[b]) for a, b in pairs), key=lambda p: (p[1], p[0]))


def test_a_second_lap_is_paired_with_the_first_where_it_comes_back():
    # Two laps of 80 keyframes (12.6 m each), the second drifted 0.15 m off the first (within
    # 0.3 m + 2% of the path between): each keyframe of the second lap gets one pair, with a
    # keyframe of the first lap near its twin 80 before. In the first lap only its last few,
    # coming back to where it began, get one (with its first ones).
    kfs = lap(0, laps=2, drift=(0.15, 0.0, 0.0))
    loops = LoopCandidates(LoopOptions(neighbourhood=0, spacing=1))
    pairs = loops.update(kfs, wanted=set())
    found = proposals_by_keyframe(pairs, kfs)
    later = [(i, j) for i, j in found if j >= 80]
    assert [j for i, j in later] == list(range(80, 160))
    assert all(abs((j - 80) - i) <= 3 for i, j in later), later
    closing = [(i, j) for i, j in found if j < 80]
    assert all(j >= 76 and i <= 4 for i, j in closing), closing
    assert loops.update(kfs, wanted=set()) == []  # each keyframe is looked at once
    assert loops.pairs == set(pairs)


def test_keyframes_come_in_batches_as_the_recording_goes_on():
    kfs = lap(0, laps=2, drift=(0.15, 0.0, 0.0))
    whole = LoopCandidates(LoopOptions(neighbourhood=0, spacing=1))
    whole.update(kfs, wanted=set())
    batched = LoopCandidates(LoopOptions(neighbourhood=0, spacing=1))
    for end in range(3, len(kfs) + 3, 3):
        batched.update(kfs[:end], wanted=set())
    assert batched.pairs == whole.pairs


def test_too_far_facing_away_or_too_recent_gives_no_pair():
    base = lap(0)[:61]  # three quarters of a lap: nothing comes back yet
    visitor = _renumbered(base[0], 61)  # at the first keyframe's place, 61 keyframes on
    assert len(LoopCandidates().update(base + [visitor], set())) == 1
    # 3 m off: beyond 0.3 m + 2% of the 9.6 m between.
    assert LoopCandidates().update(base + [_moved(visitor, (3.0, 0.0, 0.0))], set()) == []
    # At the same place, turned 90 degrees.
    assert LoopCandidates().update(base + [_turned(visitor, 90.0)], set()) == []
    # The same place 50 keyframes on: closer than min_gap (60) in keyframes.
    short = lap(0, per_lap=50)
    assert LoopCandidates().update(short + [_renumbered(short[0], 50)], set()) == []


def _moved(k, by):
    return Keyframe(k.id, k.name, k.stamp, tuple(p + d for p, d in zip(k.position, by)), k.orientation,
                    k.intrinsics, k.width, k.height)


def _turned(k, yaw_deg):
    a = math.degrees(math.atan2(k.position[1], k.position[0]))
    return Keyframe(k.id, k.name, k.stamp, k.position, facing(a + yaw_deg), k.intrinsics, k.width, k.height)


def _renumbered(k, new_id):
    return Keyframe(new_id, "%04d.png" % new_id, new_id, k.position, k.orientation, k.intrinsics, k.width, k.height)


def test_a_revisit_the_wanted_pairs_already_join_gets_none():
    # The node already paired the second lap's keyframe 100 with 19 (within 3 of its twin 20):
    # keyframes 97-103 need no pair with 16-23. A proposal joins its neighbourhoods too (3
    # keyframes either side), so the lap gets one pair every few keyframes, never two that close.
    kfs = lap(0, laps=2, drift=(0.15, 0.0, 0.0))
    wanted = {pair_of("0019.png", "0100.png")}
    found = proposals_by_keyframe(LoopCandidates(LoopOptions(spacing=1)).update(kfs, wanted), kfs)
    assert not [(i, j) for i, j in found if 97 <= j <= 103 and 16 <= i <= 22], found
    for n, (i, j) in enumerate(found):
        assert not [(a, b) for a, b in found[n + 1:] if abs(a - i) <= 3 and abs(b - j) <= 3], found
    assert len(found) >= 80 // 7  # at most 7 keyframes between two proposals along the lap
    assert max(b - a for (_, a), (_, b) in zip(found, found[1:])) <= 7 + 7, found  # the node's pair's gap aside


def test_per_keyframe_bounds_the_pairs_of_a_keyframe():
    kfs = lap(0, laps=2, drift=(0.15, 0.0, 0.0))
    two = LoopCandidates(LoopOptions(per_keyframe=2, neighbourhood=0, spacing=1))
    found = proposals_by_keyframe(two.update(kfs, set()), kfs)
    counts = {}
    for i, j in found:
        counts[j] = counts.get(j, 0) + 1
    assert max(counts.values()) == 2 and len(found) > 80
    assert LoopCandidates(LoopOptions(per_keyframe=0)).update(kfs, set()) == []


def test_one_keyframe_in_spacing_gets_a_pair():
    kfs = lap(0, laps=2, drift=(0.15, 0.0, 0.0))
    found = proposals_by_keyframe(LoopCandidates(LoopOptions(neighbourhood=0, spacing=5)).update(kfs, set()), kfs)
    later = [j for i, j in found]
    assert all(b - a >= 5 for a, b in zip(later, later[1:])), later
    assert len([j for j in later if j >= 80]) == 80 // 5


def _linked(k, revisit_of):
    return Keyframe(k.id, k.name, k.stamp, k.position, k.orientation, k.intrinsics, k.width, k.height, revisit_of)


def test_a_keyframe_the_node_links_to_a_revisit_is_paired_with_it_whatever_the_poses():
    # Most of a first lap, then keyframes made 3 m away by their drifted poses (the poses' search finds
    # nothing there), two of which the node linked to the first lap's keyframes 10 and 40 (it
    # recognised the frames before them from their images). Those two pairs are proposed, also
    # within spacing of each other and closer than min_gap; a link to a keyframe the wanted
    # pairs already join with that one, or to itself or a later one, gives none.
    first = lap(0)[:70]  # not closed: it has no loop pair of its own
    far = [_moved(k, (3.0, 0.0, 0.0)) for k in lap(70, per_lap=80)[:20]]
    far[2], far[4] = _linked(far[2], 10), _linked(far[4], 40)
    far[6] = _linked(far[6], 12)   # 76: joined already (75 with 11)
    far[8] = _linked(far[8], 78)   # not an earlier keyframe: ignored
    loops = LoopCandidates()
    found = proposals_by_keyframe(loops.update(first + far[:6], set()), first + far)
    assert found == [(10, 72), (40, 74)]
    assert loops.registered == {pair_of("0010.png", "0072.png"), pair_of("0040.png", "0074.png")}
    later = loops.update(first + far, {pair_of("0011.png", "0075.png")})
    assert later == []
    # without the links, the poses alone give nothing there
    assert LoopCandidates().update(first + [_moved(k, (0, 0, 0)) for k in far], set()) == []


def test_bad_options_are_refused():
    with pytest.raises(ValueError):
        LoopOptions(min_gap=0)
    with pytest.raises(ValueError):
        LoopOptions(max_angle_deg=0)


def test_the_work_wants_the_loop_pairs_and_the_finish_matches_and_reports_them():
    kfs = lap(0, laps=2, drift=(0.15, 0.0, 0.0))
    announced = [(a.name, b.name) for a, b in zip(kfs, kfs[1:])]
    project = FailingProject()
    project.features = {k.name for k in kfs}
    project.inlier_counts = lambda: {p: 20 for p in project.geometries}
    with_loops = LiveWork(project, continuity=False, loops=LoopOptions())
    wanted = with_loops.wanted_pairs(kfs, announced)
    loops = wanted - {pair_of(*p) for p in announced}
    assert loops and loops == with_loops.loops.pairs
    assert all(int(b[:4]) - int(a[:4]) >= 60 for a, b in loops)
    with_loops.match_all(kfs, announced)
    assert loops <= project.matched()
    without = LiveWork(FailingProject(), continuity=False)
    assert without.wanted_pairs(kfs, announced) == {pair_of(*p) for p in announced}
