"""The bridge's worker's wanted pairs and backlog, kept from the pair stream's changes
(PairStream.take_changes, live/wanted.py): each batch must match what a look at the whole session
would have it match (issue 34)."""
import random
from types import SimpleNamespace as NS

from view_selection.keyframes import continuity_pairs
from view_selection.live.stream import PairStream
from view_selection.live.work import LiveWork
from view_selection.matching.loops import LoopOptions

from test_work import FailingProject


def info(i, session="", x=None):
    # A walk round a 2 m square, again and again: revisits, so that loop pairs are proposed.
    s = (0.05 * i) % 8.0
    px, py = (s, 0.0) if s < 2 else (2.0, s - 2) if s < 4 else (6 - s, 2.0) if s < 6 else (0.0, 8 - s)
    pose = NS(position=NS(x=px if x is None else x, y=py, z=0.0), orientation=NS(w=1.0, x=0.0, y=0.0, z=0.0))
    return NS(id=i, image_name="%s%04d.png" % (session, i), stamp=NS(to_sec=lambda i=i: float(i)), pose=pose,
              intrinsics=[500.0, 500.0, 320.0, 240.0], width=640, height=480)


def msg(seq, added=(), removed=(), keyframes=(), full=False, total=None):
    return NS(sequence=seq, full=full, flushed=False, added=[NS(first=a, second=b) for a, b in added],
              removed=[NS(first=a, second=b) for a, b in removed], keyframes=list(keyframes),
              total_keyframes=total if total is not None else len(keyframes), pending_pairs=0)


def names(*pairs):
    return {("%04d.png" % a, "%04d.png" % b) for a, b in pairs}


class Session:
    """A stream, a worker and its project driven as colmap_bridge's batch() drives them."""

    def __init__(self, work, project):
        self.stream, self.work, self.project, self.seq = PairStream(), work, project, 0

    def message(self, **kwargs):
        self.seq += 1
        self.stream.apply(msg(self.seq, **kwargs))

    def batch(self, **kwargs):
        self.work.announce(self.stream.take_changes())
        kfs = self.stream.ordered_keyframes()
        self.work.extract(kfs)
        return self.work.match(kfs, **kwargs)


def matched_pairs(project, since):
    return {p for kind, items in project.runs[since:] if kind == "match" for p in items}


def test_each_batch_matches_what_a_look_at_the_whole_session_would():
    """The bridge's batches on a random session (keyframes, pairs announced and taken back and
    announced again, full messages, a new session, images that never arrive, pairs that fail,
    pairs matched by another path, batches that fail before they match): before each batch the
    backlog is computed from the whole session, as before issue 34 (the announced pairs, the
    continuity chain, the loop pairs, less what is matched, whose images have features, not
    given up, sorted), and the batch must try exactly its first ~max_batch_pairs of the first
    ~max_backlog."""
    rng = random.Random(7)
    project = FailingProject(unreadable={"0007.png", "s150001.png"})
    work = LiveWork(project, continuity=True, loops=LoopOptions(min_gap=20, spacing=2), max_backlog=12,
                    max_batch_pairs=4, max_attempts=1)
    update = work.loops.update
    s = Session(work, project)
    known, session, checked, failed = 0, "", 0, 0
    for step in range(300):
        if step == 150:  # a new session: fewer keyframes, other images
            session, known = "s15", 3
            s.message(added=[(0, 1), (0, 2)], keyframes=[info(i, session) for i in range(3)], full=True, total=3)
        elif step % 37 == 36:  # a catch-up: the whole set again, some pairs not in it
            pairs = [tuple(sorted(p)) for p in rng.sample(sorted(s.stream.announced), len(s.stream.announced) // 2)]
            s.message(added=pairs, keyframes=[info(i, session) for i in range(known)], full=True, total=known)
        else:
            new = list(range(known, known + rng.randint(0, 3)))
            known += len(new)
            added = [(i, j) for j in new for i in range(max(0, j - 4), j) if rng.random() < 0.6]
            added += [tuple(sorted(rng.sample(range(known), 2))) for _ in range(rng.randint(0, 2)) if known > 1]
            removed = rng.sample(sorted(s.stream.announced), min(len(s.stream.announced), rng.randint(0, 2)))
            s.message(added=added, removed=removed, total=known, keyframes=[info(i, session) for i in new])
        announced = sorted(s.stream.announced_names())
        if rng.random() < 0.1 and announced:  # a pair COLMAP will fail on (given up at once)
            project.bad_pairs.add(rng.choice(announced))
        if rng.random() < 0.1 and announced:  # matched by another path
            project.geometries.add(rng.choice(announced))
        fail = rng.random()
        if fail < 0.05:  # the batch fails before it matches: its changes were handed over first
            work.announce(s.stream.take_changes())
            failed += 1
            continue
        kfs = s.stream.ordered_keyframes()
        if fail < 0.1:  # the loop candidates fail after proposing: the next batch must still want them
            def failing(keyframes, wanted):
                update(keyframes, wanted)
                raise RuntimeError("a bug in the loop candidates")
            work.loops.update = failing
            work.announce(s.stream.take_changes())
            work.extract(kfs)
            try:
                work.match(kfs)
                assert False, "the failure must reach the caller"
            except RuntimeError:
                failed += 1
            work.loops.update = update
            continue
        before, runs = set(project.geometries), len(project.runs)
        given_up, deferred = set(work.pairs.failures), work.deferred  # (one failure gives a pair up)
        s.batch()
        wanted = s.stream.announced_names() | set(continuity_pairs(kfs)) | work.loops.pairs
        have = project.extracted()
        expected = sorted(p for p in wanted - before - given_up if p[0] in have and p[1] in have)
        assert work.backlog_before == len(expected), step
        assert matched_pairs(project, runs) == set(expected[:4]), step  # the oldest by name
        assert work.deferred == max(deferred, len(expected) - 12), step
        checked += 1
    assert checked > 200 and failed > 10 and work.deferred > 0 and work.loops.pairs and work.pairs.given_up_count()


def test_a_restarted_bridge_matches_only_what_its_database_lacks():
    project = FailingProject()
    project.geometries = names((0, 1), (1, 2), (0, 2))  # matched by the bridge before it restarted
    work = LiveWork(project, continuity=True, max_batch_pairs=10)
    s = Session(work, project)
    s.message(added=[(0, 1), (1, 2), (0, 2), (1, 3)], keyframes=[info(i) for i in range(4)])
    runs = len(project.runs)
    assert not s.batch()
    assert matched_pairs(project, runs) == names((2, 3), (1, 3)) and work.backlog_before == 2


def test_a_pair_taken_back_leaves_the_backlog_unless_the_chain_or_the_loops_want_it():
    project = FailingProject()
    work = LiveWork(project, continuity=True, max_batch_pairs=1)
    s = Session(work, project)
    s.message(added=[(0, 1), (0, 2), (1, 2), (1, 3)], keyframes=[info(i) for i in range(4)])
    s.batch()  # (0, 1): first by name
    s.message(removed=[(0, 2), (1, 2)], total=4)  # (1, 2) is a continuity pair too
    s.message(removed=[(1, 3)], total=4)
    s.message(added=[(1, 3)], total=4)  # taken back and announced again before the next batch
    while s.batch():
        pass
    assert project.matched() == names((0, 1), (1, 2), (2, 3), (1, 3))

    project = FailingProject()
    work = LiveWork(project, continuity=False, loops=LoopOptions(min_gap=20, spacing=1), max_batch_pairs=100)
    s = Session(work, project)
    s.message(keyframes=[info(i) for i in range(170)])  # round the square and back: loop pairs
    s.batch(limit=0)
    loop = min(work.loops.pairs)
    a, b = (int(name[:4]) for name in loop)
    s.message(added=[(a, b)], total=170)
    s.message(removed=[(a, b)], total=170)
    s.batch()
    assert project.matched() == work.loops.pairs and loop in project.matched()


def test_a_batch_that_fails_while_the_loops_propose_wants_their_pairs_in_the_next():
    project = FailingProject()
    work = LiveWork(project, continuity=False, loops=LoopOptions(min_gap=20, spacing=1), max_batch_pairs=100)
    s = Session(work, project)
    update = work.loops.update

    def failing(keyframes, wanted):
        update(keyframes, wanted)  # pairs proposed, then a failure before the work hears of them
        raise RuntimeError("a bug in the loop candidates")
    work.loops.update = failing
    s.message(keyframes=[info(i) for i in range(170)])
    try:
        s.batch()
        assert False, "the failure must reach the caller"
    except RuntimeError:
        pass
    work.loops.update = update
    assert work.loops.pairs and not project.matched()
    s.batch()
    assert project.matched() == work.loops.pairs


def test_the_finish_matches_its_own_pairs_and_the_batches_after_it_go_on_with_the_stream_s():
    """build_model's match_all takes the node's final selection, whole; the stream's changes
    handed to the batches after it are against what the batches had, not against the finish's."""
    project = FailingProject()
    work = LiveWork(project, continuity=False, match_delay=1e6)  # announced pairs wait: the finish takes them
    now = [0.0]
    work.now = lambda: now[0]
    s = Session(work, project)
    s.message(added=[(0, 1), (1, 2)], keyframes=[info(i) for i in range(3)])
    s.batch()
    assert not project.matched()
    work.match_all(s.stream.ordered_keyframes(), sorted(names((0, 1), (0, 2))))  # the node's final selection
    assert project.matched() == names((0, 1), (0, 2))
    s.message(added=[(2, 3)], keyframes=[info(3)], total=4)
    s.batch(quiet=True)  # the stream still announces (1, 2): matched now
    assert project.matched() == names((0, 1), (0, 2), (1, 2), (2, 3))


def test_a_whole_set_given_each_time_is_compared_with_the_one_held():
    project = FailingProject()
    kfs = PairStream()
    kfs.apply(msg(1, keyframes=[info(i) for i in range(5)]))
    kfs = kfs.ordered_keyframes()
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=1)
    work.match(kfs, [("0002.png", "0000.png"), ("0001.png", "0003.png")])  # a list: sorted within here
    assert project.matched() == names((0, 2))
    work.match(kfs, {("0001.png", "0004.png")})  # (1, 3) is no longer announced
    work.match(kfs, {("0001.png", "0004.png")})
    assert project.matched() == names((0, 2), (1, 4))
    assert work.wanted_pairs(kfs) == names((1, 4))
