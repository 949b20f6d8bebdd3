"""The bridge's work on its project, with a project that fails the way COLMAP does: a run over a
list fails as a whole when one item in it is bad. The real COLMAP is in the rostests."""
import math
import types

from view_selection.colmap.project import ProjectError
from view_selection.keyframes import Keyframe
from view_selection.live.work import LiveWork


class FailingProject:
    """hanging_images, hanging_pairs: a run that lists one of them times out (as a COLMAP that
    hangs on it every time, killed at its timeout); hang_everything: every run does."""

    def __init__(self, bad_images=(), bad_pairs=(), fail_everything=False, unreadable=(), hanging_images=(),
                 hanging_pairs=(), hang_everything=False):
        self.bad_images, self.bad_pairs, self.unreadable = set(bad_images), set(bad_pairs), set(unreadable)
        self.hanging_images, self.hanging_pairs = set(hanging_images), set(hanging_pairs)
        self.fail_everything, self.hang_everything = fail_everything, hang_everything
        self.features, self.geometries = set(), set()
        self.runs = []
        self.ledgered = []
        self.cancelled = False

    def register(self, keyframes):
        pass

    def has_image(self, name):
        return True

    def extracted(self, refresh=()):
        return set(self.features)

    def matched(self, refresh=()):
        return set(self.geometries)

    def extract(self, keyframes):
        names = [k.name for k in keyframes]
        self.runs.append(("extract", names))
        if self.hang_everything or self.hanging_images & set(names):
            raise ProjectError("'colmap feature_extractor' did not finish within 130 s and was killed", timed_out=True)
        if self.fail_everything or self.bad_images & set(names):
            raise ProjectError("'colmap feature_extractor' failed (exit 1)")
        self.features |= set(names) - self.unreadable  # COLMAP skips what it cannot read

    def match(self, pairs):
        self.runs.append(("match", list(pairs)))
        if self.hang_everything or self.hanging_pairs & set(pairs):
            raise ProjectError("'colmap matches_importer' did not finish within 240 s and was killed", timed_out=True)
        if self.fail_everything or self.bad_pairs & set(pairs):
            raise ProjectError("'colmap matches_importer' failed (exit 3)")
        self.geometries |= set(pairs)

    def ledger(self, what, items):
        self.ledgered += [(what, i) for i in items]

    def ledger_items(self, what):
        return [i for w, i in self.ledgered if w == what]


def keyframes(n):
    return [Keyframe(i, "%03d.png" % i, i, (i, 0, 0), (1, 0, 0, 0), (500, 500, 320, 240), 640, 480) for i in range(n)]


def chain(kfs):
    return [(a.name, b.name) for a, b in zip(kfs, kfs[1:])]


def test_one_bad_pair_costs_its_neighbours_nothing():
    kfs = keyframes(25)
    pairs = chain(kfs)
    bad = pairs[13]
    project = FailingProject(bad_pairs=[bad])
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=24, max_attempts=3)
    assert not work.match(kfs, pairs)
    assert project.matched() == set(pairs) - {bad}
    assert len(project.runs) <= 2 * math.ceil(math.log2(24)) + 1
    assert work.pairs.suspect(bad) and not work.pairs.given_up(bad)


def test_colmap_failing_on_everything_is_found_in_log_n_runs():
    kfs = keyframes(33)
    project = FailingProject(fail_everything=True)
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=32)
    work.match(kfs, chain(kfs))
    assert len(project.runs) <= 2 * math.ceil(math.log2(32)) + 2  # the budget, not one run per pair
    assert all(work.pairs.suspect(p) for p in chain(kfs))


def test_a_pair_that_keeps_failing_is_given_up_and_ledgered():
    kfs = keyframes(4)
    pairs = chain(kfs)
    project = FailingProject(bad_pairs=[pairs[0]])
    project.features = {k.name for k in kfs}
    now = [0.0]
    work = LiveWork(project, continuity=False, max_attempts=3)
    work.pairs.clock = lambda: now[0]
    for _ in range(10):
        work.match(kfs, pairs)
        now[0] += 1000.0  # past every backoff
    assert work.pairs.given_up(pairs[0])
    assert project.ledgered == [("skipped-pair", "%s %s" % pairs[0])]
    assert sum(1 for kind, items in project.runs if items == [pairs[0]]) == 3  # then never again
    assert work.skipped()["pairs"][0]["item"] == "%s %s" % pairs[0]
    assert "exit 3" in work.skipped()["pairs"][0]["error"]


def test_what_an_earlier_run_gave_up_gets_one_more_try_after_a_restart():
    """A bridge killed and started again on its project reads what it gave up from the ledger:
    an image or a pair that fails COLMAP costs one more run (for a hang, one more timeout), not
    ~max_attempts; a pair that works now (a fault mended) is matched."""
    kfs = keyframes(7)
    pairs = chain(kfs)[:5]  # the last keyframe's image is bad: no pair of it
    project = FailingProject(hanging_pairs=[pairs[1]], bad_images=[kfs[6].name])
    project.features = {k.name for k in kfs[:6]}
    project.ledgered = [("skipped-pair", "%s %s" % pairs[1]), ("skipped-pair", "%s %s" % pairs[3]),
                        ("skipped-image", kfs[6].name), ("matched", "%s %s" % pairs[0])]
    work = LiveWork(project, continuity=False, max_attempts=3)
    assert not work.pairs.given_up(pairs[1]) and work.pairs.suspect(pairs[1])
    assert not work.images.given_up(kfs[6].name)
    work.extract(kfs)
    work.match_all(kfs, pairs)
    assert sum(1 for kind, items in project.runs if items == [pairs[1]]) == 1  # one more, alone
    assert sum(1 for kind, items in project.runs if kind == "extract" and kfs[6].name in items) == 1
    assert work.pairs.given_up(pairs[1]) and work.images.given_up(kfs[6].name)
    assert pairs[3] in project.geometries and not work.pairs.given_up(pairs[3])  # mended since
    skipped = {s["item"]: s for s in work.skipped()["pairs"]}
    assert set(skipped) == {"%s %s" % pairs[1]}
    assert skipped["%s %s" % pairs[1]]["attempts"] == 3 and "240 s" in skipped["%s %s" % pairs[1]]["error"]


def test_an_unreadable_image_is_retried_with_a_wait_not_every_batch():
    kfs = keyframes(5)
    project = FailingProject(unreadable=["002.png"])
    now = [0.0]
    work = LiveWork(project, continuity=False)
    work.images.clock = lambda: now[0]
    work.extract(kfs)
    assert project.extracted() == {k.name for k in kfs} - {"002.png"}
    runs = len(project.runs)
    for _ in range(5):  # batches one second apart: the image waits
        now[0] += 1.0
        work.extract(kfs)
    assert len(project.runs) == runs + 1  # one retry after the first wait (2 s)


def test_one_bad_image_does_not_stop_the_others_or_the_matching():
    kfs = keyframes(6)
    project = FailingProject(bad_images=["003.png"])
    work = LiveWork(project, continuity=True)
    work.extract(kfs)
    assert project.extracted() == {k.name for k in kfs} - {"003.png"}
    work.match(kfs, [])
    assert project.matched() == {p for p in chain(kfs) if "003.png" not in p}


def timeouts(project):
    """The runs that timed out (each cost a COLMAP timeout)."""
    return [(kind, items) for kind, items in project.runs
            if project.hang_everything or (project.hanging_images if kind == "extract" else project.hanging_pairs)
            & set(items)]


def test_a_pair_that_hangs_every_time_is_the_only_one_charged_and_skipped():
    kfs = keyframes(25)
    pairs = chain(kfs)
    hung = pairs[9]
    project = FailingProject(hanging_pairs=[hung])
    project.features = {k.name for k in kfs}
    now = [0.0]
    work = LiveWork(project, continuity=False, max_batch_pairs=24, max_attempts=3)
    work.pairs.clock = lambda: now[0]
    work.match(kfs, pairs)
    # The batch of 24 timed out once; then each of its pairs alone: only the hung one failed.
    assert project.matched() == set(pairs[:24]) - {hung}
    assert work.pairs.failures == {hung: 1}
    assert len(timeouts(project)) == 2
    for _ in range(6):
        now[0] += 1000.0  # past every backoff
        work.match(kfs, pairs)
    assert project.matched() == set(pairs) - {hung}
    assert work.pairs.given_up(hung)
    assert [s["item"] for s in work.skipped()["pairs"]] == ["%s %s" % hung]
    assert "did not finish" in work.skipped()["pairs"][0]["error"]
    assert project.ledgered == [("skipped-pair", "%s %s" % hung)]
    assert len(timeouts(project)) == 1 + 3  # the batch, then three tries alone; never again


def test_an_image_that_hangs_every_time_is_the_only_one_skipped():
    kfs = keyframes(12)
    project = FailingProject(hanging_images=["004.png"])
    now = [0.0]
    work = LiveWork(project, continuity=True, max_attempts=3)
    work.images.clock = lambda: now[0]
    for _ in range(5):
        work.extract(kfs)
        now[0] += 1000.0
    assert project.extracted() == {k.name for k in kfs} - {"004.png"}
    assert work.images.given_up("004.png") and work.images.failures == {"004.png": 3}
    assert len(timeouts(project)) == 1 + 3
    work.match(kfs, [])
    assert project.matched() == {p for p in chain(kfs) if "004.png" not in p}


def test_a_colmap_that_hangs_on_everything_costs_a_bounded_number_of_timeouts_per_batch():
    kfs = keyframes(25)
    project = FailingProject(hang_everything=True)
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=24)
    work.match(kfs, chain(kfs))
    # The batch, then two alone in a row: COLMAP hangs on everything; the rest wait uncharged.
    assert len(project.runs) == 1 + LiveWork.ALONE_TIMEOUTS_IN_A_ROW
    assert len(work.pairs.failures) == LiveWork.ALONE_TIMEOUTS_IN_A_ROW
    assert all(work.pairs.suspect(p) for p in chain(kfs)[:24])


def test_a_cancelled_run_charges_nobody():
    kfs = keyframes(6)
    project = FailingProject()
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False)

    def cancelled(pairs):
        project.cancelled = True
        raise ProjectError("'colmap matches_importer' (matching) was cancelled")

    project.match = cancelled
    work.match(kfs, chain(kfs))
    assert work.pairs.failures == {} and work.skipped(all_failed=True)["pairs"] == []


def test_the_finish_matches_every_wanted_pair_whatever_max_backlog_is():
    # A small ~max_backlog (5 of 40 pairs), so that the recording's batches leave most pairs for
    # the finish: its matching must take them all (issue 34: the finish once matched at most
    # ~max_backlog and said nothing).
    kfs = keyframes(41)
    pairs = chain(kfs)
    project = FailingProject()
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_backlog=5, max_batch_pairs=3)
    assert work.match(kfs, pairs)  # a batch while recording: 3 pairs, more waiting
    assert len(project.matched()) == 3 and work.deferred == 40 - 5
    seen = []
    runs = work.match_all(kfs, pairs, batch=8, progress=lambda done, total: seen.append((done, total)))
    assert project.matched() == set(pairs)
    assert runs == 5 and seen[-1] == (37, 37)
    assert work.lost_pairs(set(pairs), project.matched(), project.extracted(), []) == []


def test_a_wanted_pair_not_in_the_model_is_named_with_its_reason():
    kfs = keyframes(6)
    pairs = chain(kfs)
    project = FailingProject(bad_pairs=[pairs[0]], bad_images=["004.png"])
    work = LiveWork(project, continuity=False, max_attempts=1)
    work.extract(kfs)
    work.match_all(kfs, pairs)
    lost = {x["pair"]: x["reason"] for x in work.lost_pairs(set(pairs), project.matched(), project.extracted(),
                                                            ["005.png"])}
    assert set(lost) == {"000.png 001.png", "003.png 004.png", "004.png 005.png"}
    assert "exit 3" in lost["000.png 001.png"] and lost["000.png 001.png"].startswith("failed 1 time")
    assert lost["003.png 004.png"].startswith("the image 004.png has no features")
    assert lost["004.png 005.png"] == "the image 004.png has no features: 'colmap feature_extractor' failed (exit 1)" \
        or lost["004.png 005.png"].startswith("the image 005.png never arrived")


def test_out_of_time_stops_the_work_and_charges_nobody():
    kfs = keyframes(8)
    project = FailingProject()
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False)

    def out_of_time(pairs):
        raise ProjectError("out of time in matching: the finish's budget at shutdown is spent", out_of_time=True)

    project.match = out_of_time
    try:
        work.match(kfs, chain(kfs))
        assert False, "out of time must stop the finish's work"
    except ProjectError as e:
        assert e.out_of_time
    assert work.pairs.failures == {} and not any(work.pairs.suspect(p) for p in chain(kfs))


def test_items_that_fail_alone_one_after_another_stop_the_runs_alone():
    kfs = keyframes(20)
    project = FailingProject(fail_everything=True)
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=24)
    now = [0.0]
    work.pairs.clock = lambda: now[0]
    work.match(kfs, chain(kfs))  # the batch halved: every pair charged once
    runs = len(project.runs)
    now[0] += 1000.0  # past the backoff
    work.match(kfs, chain(kfs))  # each is a suspect now, tried alone: four in a row fail, the rest wait
    assert len(project.runs) - runs == LiveWork.ALONE_FAILURES_IN_A_ROW


class GuidedProject(FailingProject):
    """A backend that matches by the poses (as matching.backend.PoseGuidedBackend): the pairs in
    `falls_back` cannot be matched so and go to COLMAP's matcher (match_fallback), which fails or
    hangs as FailingProject's runs do."""

    def __init__(self, falls_back=(), **kwargs):
        super().__init__(**kwargs)
        self.falls_back = set(falls_back)
        self.guided = []  # the pairs matched by the poses, each time one was tried

    def match(self, pairs, defer_fallback=None):
        fallback = [p for p in pairs if p in self.falls_back]
        self.guided += [p for p in pairs if p not in self.falls_back]
        self.geometries |= set(pairs) - self.falls_back
        if fallback and defer_fallback is not None:
            defer_fallback(fallback)
        elif fallback:
            self.match_fallback(fallback)

    def match_fallback(self, pairs):
        FailingProject.match(self, pairs)


def fallback_runs(project):
    return [items for kind, items in project.runs if kind == "match"]


def test_fallbacks_of_several_batches_go_to_colmap_in_one_run():
    # Every other pair falls back; batches of 4 pairs: 2 fallbacks a batch. Until
    # FALLBACK_RUN_PAIRS of them wait, no run of COLMAP's matcher (each run costs ~0.06 s CPU
    # beside its pairs), and a waiting pair is neither tried again by the poses nor charged.
    from view_selection.live import work as work_module
    n = 2 * work_module.FALLBACK_RUN_PAIRS + 6
    kfs = keyframes(n + 1)
    pairs = chain(kfs)
    project = GuidedProject(falls_back=pairs[1::2])
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=4)
    clock = [0.0]
    work.now = lambda: clock[0]
    batches = 0
    while not fallback_runs(project):
        work.match(kfs, pairs)
        batches += 1
        assert batches <= n
    (run,) = fallback_runs(project)
    assert len(run) == work_module.FALLBACK_RUN_PAIRS and set(run) <= set(pairs[1::2])
    assert batches == work_module.FALLBACK_RUN_PAIRS // 2
    assert len(project.guided) == len(set(project.guided))  # nothing guided twice
    assert not work.pairs.failures and work.status["fallback_waiting"] == 0
    # The rest of the guided pairs: their fallbacks wait (fewer than a run's worth, not long yet).
    while work.match(kfs, pairs):
        pass
    work.match(kfs, pairs)
    assert len(fallback_runs(project)) == 1 and work.status["fallback_waiting"] > 0
    assert set(project.guided) == set(pairs[0::2])
    # Waiting FALLBACK_MAX_WAIT: they run, though fewer than a run's worth.
    clock[0] += work_module.FALLBACK_MAX_WAIT
    work.match(kfs, pairs)
    assert len(fallback_runs(project)) == 2 and project.matched() == set(pairs)
    assert work.status["fallback_waiting"] == 0 and work.status["backlog_pairs"] == 0


def test_waiting_fallbacks_run_when_no_keyframe_came_for_a_while_and_at_the_finish():
    kfs = keyframes(7)
    pairs = chain(kfs)
    project = GuidedProject(falls_back=pairs[:2])
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=3)
    work.match(kfs, pairs)
    assert not fallback_runs(project) and project.matched() == {pairs[2]}
    work.match(kfs, pairs, quiet=True)  # no keyframe for a while: the finish may be near
    assert fallback_runs(project) == [pairs[:2]] and project.matched() == set(pairs)

    # The finish takes what waits, whatever the count and the wait.
    project = GuidedProject(falls_back=pairs[:2])
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=3)
    work.match(kfs, pairs)
    work.match_all(kfs, pairs)
    assert fallback_runs(project) == [pairs[:2]] and project.matched() == set(pairs)
    assert work.lost_pairs(set(pairs), project.matched(), project.extracted(), []) == []


def test_a_bad_pair_in_a_run_of_waiting_fallbacks_costs_its_neighbours_nothing():
    from view_selection.live import work as work_module
    kfs = keyframes(work_module.FALLBACK_RUN_PAIRS + 1)
    pairs = chain(kfs)
    bad = pairs[5]
    project = GuidedProject(falls_back=pairs, bad_pairs=[bad])
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=len(pairs))
    work.match(kfs, pairs)  # all fall back: one run of them, halved where it fails
    assert project.matched() == set(pairs) - {bad}
    assert work.pairs.failures == {bad: 1} and not project.guided
    assert len(fallback_runs(project)) <= 2 * (len(pairs) - 1).bit_length() + 2
    # Tried again (alone: it failed before) once its wait is over, as any failed pair.
    work.pairs.not_before.clear()
    work.match(kfs, pairs, quiet=True)
    assert fallback_runs(project)[-1] == [bad] and work.pairs.failures == {bad: 2}


def test_a_waiting_fallback_no_longer_wanted_is_not_matched():
    kfs = keyframes(5)
    pairs = chain(kfs)
    project = GuidedProject(falls_back=[pairs[0]])
    project.features = {k.name for k in kfs}
    work = LiveWork(project, continuity=False, max_batch_pairs=4)
    work.match(kfs, pairs)
    assert work.fallback_waiting.keys() == {pairs[0]}
    work.match(kfs, pairs[1:], quiet=True)  # the node took the pair back
    assert not fallback_runs(project) and not work.fallback_waiting


def test_a_batch_wants_what_a_fresh_look_at_the_whole_list_wants():
    """wanted_pairs keeps the continuity chain and the loop candidates as keyframes come, moved
    and in a new session: each batch's answer is the one it gives when made to look at the whole
    list (its scan forgotten: every keyframe changed), as it did before issue 34's batches."""
    import random
    from view_selection.matching.loops import LoopOptions
    rng = random.Random(5)

    def walk(n, session):  # a lap of a 2 m square, again and again: revisits for the loop pairs
        out = []
        for i in range(n):
            s = (0.05 * i) % 8.0
            x, y = (s, 0.0) if s < 2 else (2.0, s - 2) if s < 4 else (6 - s, 2.0) if s < 6 else (0.0, 8 - s)
            out.append(Keyframe(i, "%s%04d.png" % (session, i), i, (x, y, 0), (1, 0, 0, 0), (500, 500, 320, 240),
                                640, 480))
        return out

    def pairs_of(kfs):
        return {(a.name, b.name) for a, b in zip(kfs, kfs[3:]) if rng.random() < 0.5}

    work = LiveWork(FailingProject(), continuity=True, loops=LoopOptions())
    whole = LiveWork(FailingProject(), continuity=True, loops=LoopOptions())
    session, n, kfs = "a", 0, []
    for step in range(60):
        if step == 40:
            session, n = "b", 10  # another session: fewer keyframes, other images
        n += rng.randint(0, 12)
        kfs = walk(n, session)[:n] if step in (0, 40) else kfs[:] + walk(n, session)[len(kfs):n]
        for _ in range(rng.randint(0, 2)):  # a keyframe the node moved: a new object
            if kfs:
                i = rng.randrange(len(kfs))
                k = kfs[i]
                kfs[i] = Keyframe(k.id, k.name, k.stamp, (k.position[0], k.position[1], 0.01), k.orientation,
                                  k.intrinsics, k.width, k.height)
        announced = pairs_of(kfs)
        whole.seen["wanted"].forget()
        wanted = work.wanted_pairs(kfs, announced)
        assert wanted == whole.wanted_pairs(kfs, announced), step
        assert {(a.name, b.name) for a, b in zip(kfs, kfs[1:])} <= wanted  # the chain of this list
    assert work.loops.pairs  # the walk revisits: loop pairs were proposed and compared


def test_a_keyframe_whose_image_comes_later_is_extracted_when_it_comes():
    kfs = keyframes(6)
    project = FailingProject()
    arrived = {k.name for k in kfs} - {"002.png", "004.png"}
    project.has_image = lambda name: name in arrived
    work = LiveWork(project, continuity=False)
    work.extract(kfs)
    assert project.extracted() == arrived
    more = keyframes(8)
    more[:6] = kfs  # the same keyframes, two new ones
    arrived |= {"004.png", "006.png", "007.png"}
    work.extract(more)
    assert project.extracted() == arrived
    arrived.add("002.png")
    work.extract(more)
    assert project.extracted() == {k.name for k in more}
    shorter = [Keyframe(i, "new%03d.png" % i, i, (i, 0, 0), (1, 0, 0, 0), (500, 500, 320, 240), 640, 480)
               for i in range(3)]
    arrived |= {k.name for k in shorter}
    runs = len(project.runs)
    work.extract(shorter)  # another session: its images, none of the old ones again
    assert project.runs[runs:] == [("extract", [k.name for k in shorter])]


def test_a_matched_pair_taken_back_is_ledgered_one_never_matched_is_not():
    kfs = keyframes(4)
    project = FailingProject()
    work = LiveWork(project, continuity=False)
    work.extract(kfs)
    work.match(kfs, [("000.png", "001.png"), ("001.png", "002.png")])
    assert work.taken_back([("000.png", "001.png"), ("002.png", "003.png")]) == 1
    assert project.ledger_items("taken-back") == ["000.png 001.png"]


def delayed_work(kfs, continuity):
    """A LiveWork with ~match_delay 10 s on a clock the test sets (now[0]), its keyframes extracted."""
    project = FailingProject()
    now = [0.0]
    work = LiveWork(project, continuity=continuity, match_delay=10.0)
    work.now = lambda: now[0]
    work.extract(kfs)
    return project, work, now


def test_an_announced_pair_waits_match_delay_and_one_taken_back_meanwhile_is_never_matched():
    kfs = keyframes(6)
    project, work, now = delayed_work(kfs, continuity=True)
    stays, leaves, late = ("000.png", "002.png"), ("001.png", "003.png"), ("002.png", "004.png")
    work.match(kfs, [stays, leaves])
    assert project.matched() == set(chain(kfs))  # continuity pairs at once, announced ones wait
    now[0] = 6.0
    work.match(kfs, [stays, late])  # `leaves` taken back: it is not matched, now or later
    assert stays not in project.matched()
    now[0] = 10.0
    work.match(kfs, [stays, late])
    assert stays in project.matched() and late not in project.matched()  # `late` came at 6 s
    now[0] = 12.0
    work.match(kfs, [stays, late], quiet=True)  # the keyframes paused: everything waiting now
    assert late in project.matched() and leaves not in project.matched()


def test_pairs_within_match_delay_wait_through_pauses_of_keyframes_until_the_recording_pauses():
    kfs = keyframes(6)
    project, work, now = delayed_work(kfs, continuity=False)
    pair = ("000.png", "002.png")
    work.match(kfs, [pair])
    now[0] = 2.0
    work.match(kfs, [pair], quiet=True, paused=False)  # keyframes paused, frames go on: a revisit
    assert not project.matched()
    now[0] = 3.0
    work.match(kfs, [pair], quiet=False, paused=True)  # the node said its frames stopped
    assert project.matched() == {pair}


def test_the_finish_matches_the_pairs_that_wait_for_match_delay():
    kfs = keyframes(5)
    project = FailingProject()
    work = LiveWork(project, continuity=False, match_delay=1e6)
    work.extract(kfs)
    pairs = [("000.png", "002.png"), ("001.png", "003.png")]
    work.match(kfs, pairs)
    assert not project.matched()
    work.match_all(kfs, pairs)
    assert project.matched() == set(pairs)


def test_keyframes_a_failed_register_left_out_are_registered_by_the_next_batch():
    kfs = keyframes(4)
    project = FailingProject()
    registered, fail = [], [True]

    def register(given):
        if fail[0]:
            fail[0] = False
            raise ProjectError("database is locked")
        registered.extend(k.name for k in given)
    project.register = register
    work = LiveWork(project, continuity=False)
    try:
        work.extract(kfs)
    except ProjectError:
        pass
    work.extract(kfs)
    assert set(registered) == {k.name for k in kfs}


def test_the_matching_is_behind_once_a_batch_left_several_batches_of_due_pairs_and_the_refinement_hears_it():
    import itertools
    from view_selection.live import work as live_work
    kfs = keyframes(40)
    names = [k.name for k in kfs]
    steps = []
    project = FailingProject()
    work = LiveWork(project, continuity=False, refinement=types.SimpleNamespace(
        step=lambda behind=False: steps.append(behind)))
    work.extract(kfs)
    limit = work.max_batch_pairs * live_work.BEHIND_BATCHES
    pairs = list(itertools.combinations(names, 2))[:work.max_batch_pairs + limit]
    work.match(kfs, pairs)  # a batch's worth matched, exactly BEHIND_BATCHES' worth left: not behind
    assert work.due_left == limit and not work.behind()
    work.refine_in_background()
    assert steps == [False]
    more = list(itertools.combinations(names, 2))[:2 * work.max_batch_pairs + limit + 1]
    work.match(kfs, more)  # one more pair left than that: behind
    assert work.due_left == limit + 1 and work.behind()
    work.refine_in_background()
    assert steps == [False, True]
    while work.match(kfs, more):
        pass
    assert work.due_left == 0 and not work.behind()  # caught up
