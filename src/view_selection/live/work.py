"""The bridge's work on its COLMAP project, without ROS: features of new keyframes, matches of
announced pairs in bounded batches, and the model at the end, with every failure skipped,
recorded (DIR/ledger.txt, report.json) and retried with a growing wait a bounded number of
times. One bad image or pair never holds up the rest: an item that failed once is tried alone
afterwards, so a batch that fails names its culprit.
"""
import time

from .. import geometry
from ..colmap import durable
from ..colmap.project import ColmapProject, ProjectError
from ..keyframes import ContinuityChain, continuity_pairs, pair_of
from ..matching.loops import LoopCandidates
from .attempts import Attempts
from .changes import KeyframeChanges
from .stream import AnnouncedChanges
from .wanted import WantedPairs


# Pairs a run of the finish's matching takes (match_all): large enough that COLMAP's fallback
# matcher starts seldom, small enough that a run that fails is halved over few pairs and that
# progress is reported as it goes.
FINISH_BATCH_PAIRS = 256

# The pairs that fall back to COLMAP's matcher (matches_importer) while the recording goes on wait
# for a run of at least this many, or FALLBACK_MAX_WAIT seconds, or a while without keyframes: a run
# costs ~0.06 s CPU beside its ~0.04 s a pair, and a batch of 24 pairs had 3.75 fallbacks (a
# 10-minute walk: 557 runs for 2,092 pairs).
FALLBACK_RUN_PAIRS = 16
FALLBACK_MAX_WAIT = 10.0
# The matching is behind (LiveWork.behind) once a batch left more than this many batches' worth
# of due pairs for later: a refinement that runs beside it yields the CPU then (issue 34: a run
# at the end of a 30-minute walk held the bridge's batches to one every 2.5 s for its last 30 s,
# and the finish had 379 pairs left to match).
BEHIND_BATCHES = 4


class LiveWork:
    def __init__(self, project: ColmapProject, continuity=True, max_backlog=2000, max_batch_pairs=24,
                 max_attempts=3, log=None, backend=None, triangulation="live", refinement=None, loops=None,
                 match_delay=0.0):
        """backend: what extracts and matches (register, extract, match, extracted, matched,
        has_image): the project itself (COLMAP's commands) or matching.backend's pose-guided
        one. triangulation: "live" (live/model.py: points as pairs verify, the finish writes
        them) or "colmap" (point_triangulator over the whole model at the finish).
        refinement: refinement.refiner.ModelRefinement (issue 29: the known-pose model refined,
        DIR/sparse/0 refined, DIR/sparse/unrefined kept), or None. loops: matching.loops.LoopOptions
        (pairs across revisits the poses do not show, wanted beside the announced ones: what lets
        the refinement see a long session's drift), or None. match_delay [s]: an announced pair is
        matched once a batch wanted it this long ago (the node takes some back soon after; the
        continuity and loop pairs, which stay, and every pair when the keyframes pause or at the
        finish, at once)."""
        from ..matching.backend import StageClock
        from .model import LiveModel
        self.project = project
        self.refinement = refinement
        self.backend = backend or project
        if triangulation not in ("live", "colmap"):
            raise ValueError("triangulation: live or colmap, not %r" % triangulation)
        self.triangulation = triangulation
        self.clock = StageClock()
        self.continuity = continuity
        self.max_backlog, self.max_batch_pairs = int(max_backlog), max(1, int(max_batch_pairs))
        self.match_delay = max(0.0, float(match_delay))
        self.wanted_since = {}  # pair waiting to be matched -> when a batch first wanted it
        self.images = Attempts(max_attempts)
        self.pairs = Attempts(max_attempts)
        self.log = log or (lambda level, text: None)
        self.model = LiveModel() if triangulation == "live" else None
        self.loops = LoopCandidates(loops) if loops is not None else None
        self.fed_poses = {}        # name -> the pose the model has for it
        self.unfed_pairs = []      # verified pairs (image ids) the live model does not have yet
        self.fed_keyframes = {}    # name -> the Keyframe object last fed with its keypoints
        # A batch looks at the keyframes that changed since the one before (live/changes.py), and
        # at those still waiting for something, never at the whole session (issue 34):
        self.seen = {"extract": KeyframeChanges(), "wanted": KeyframeChanges(), "model": KeyframeChanges()}
        self.unextracted = {}      # name -> Keyframe: no features yet (no image, failed, or new)
        self.unfed = {}            # name -> Keyframe: the live model has not taken its pose or keypoints
        self.chain = ContinuityChain()  # the continuity pairs of the keyframes so far
        # The wanted pairs and the backlog of those not matched, kept from what changes
        # (live/wanted.py): the announced pairs as the caller gives them, the chain's and the
        # loops' as they grow. `_rebuild_wanted`: a batch failed while it brought them up to
        # date; the next one builds the backlog again from everything wanted.
        self.wanted = WantedPairs(self._wanted_beside)
        self._rebuild_wanted = False
        self.backlog_max = 0
        self.backlog_before = 0
        self.due_left = 0  # pairs the last batch found due and left for the next (behind)
        self.status = {}  # the last batch's figures: keyframes, images extracted and waiting, pairs
        self.deferred = 0  # pairs beyond ~max_backlog at some point, left for the finish
        # pair -> when it fell back: waiting for a run of COLMAP's matcher with others (backends
        # that match by the poses and can hand their fallbacks over: match_fallback)
        self.fallback_waiting = {}
        self.fallback_batched = hasattr(self.backend, "match_fallback")
        self.now = time.monotonic  # the fallbacks' clock
        self.errors = []   # the last few, for the report
        # The pose the live model takes for a keyframe (its node pose), unless a refinement that
        # runs beside the matching (refinement/local.py) attaches its own: refined poses.
        self.pose_of = lambda k, iid: geometry.world_to_camera(k.position, k.orientation)
        if hasattr(refinement, "attach"):
            refinement.attach(self)
        # What an earlier run on this project gave up (DIR/ledger.txt) gets one more try, not
        # ~max_attempts: a COLMAP call that hangs on it costs its timeout once more, not three
        # times (a restarted bridge spent 57 s so in live_colmap_faults), and a fault mended
        # since is found.
        why = "given up before the bridge started again (ledger.txt)"
        for name in project.ledger_items("skipped-image"):
            self.images.given_up_before(name, why)
        for pair in project.ledger_items("skipped-pair"):
            names = pair.split(" ")
            if len(names) == 2:
                self.pairs.given_up_before(tuple(names), why)

    def error(self, text):
        self.log("error", text)
        self.errors.append({"at": time.time(), "error": text})
        del self.errors[:-20]

    # -- running COLMAP on a batch, with the culprit found --------------------------------------
    # A run of several items that timed out names no culprit and charges nobody: its items are
    # suspected and each is tried alone. Two runs alone in a row that time out say COLMAP hangs
    # on everything now: the rest stay suspected, uncharged, for the next batch (so one call
    # costs at most the batch's timeout and two single-item timeouts); so do four failures in a
    # row of any kind (COLMAP failing on everything: a run each would cost n runs, not log n).
    ALONE_TIMEOUTS_IN_A_ROW = 2
    ALONE_FAILURES_IN_A_ROW = 4

    def _attempt(self, items, run, done, attempts, kind, ledger_kind):
        """Runs `run(items)`; the items `done()` does not list afterwards failed; returns them.

        Items suspected before (a failure, or a run that hung) are each tried alone; the others
        in one run. When that run fails (COLMAP exited non-zero) with several items, each half
        is tried on its own, so one bad item costs its neighbours nothing (about 2 log2 n runs;
        the halving has a budget of 2 log2 n + 2 runs: when COLMAP fails on everything, the rest
        are charged without running). When a run of several times out, it is not halved (a
        hung COLMAP would cost a timeout per half): its items are suspected, not charged, and
        each is tried alone, so an item that hangs COLMAP every time is the only one charged
        (issue 35: it took up to 23 neighbours with it)."""
        alone = [i for i in items if attempts.suspect(i)]
        batch = [i for i in items if not attempts.suspect(i)]
        failed = []
        if batch:
            budget = [2 * max(1, len(batch) - 1).bit_length() + 2]
            failed += self._halving(batch, run, done, attempts, kind, ledger_kind, budget, alone)
        timeouts, failures = 0, 0  # in a row
        for n, i in enumerate(alone):
            if (self.project.cancelled or timeouts >= self.ALONE_TIMEOUTS_IN_A_ROW
                    or failures >= self.ALONE_FAILURES_IN_A_ROW):
                failed += alone[n:]  # not tried now (a suspect from a hang stays uncharged)
                break
            f, error, timed_out = self._run([i], run, done, attempts)
            timeouts = timeouts + 1 if timed_out else 0
            failures = failures + 1 if f else 0
            self._charge(f, error, attempts, kind, ledger_kind)
            failed += f
        return failed

    def _halving(self, items, run, done, attempts, kind, ledger_kind, budget, hung):
        """_attempt's batch: run, halved where it fails; the items of a run of several that timed
        out are suspected and go to `hung` (tried alone by the caller); returns the items
        charged."""
        if budget[0] <= 0:
            failed, error, timed_out = list(items), "not tried: COLMAP failed on the whole batch", False
        else:
            budget[0] -= 1
            failed, error, timed_out = self._run(items, run, done, attempts)
        if timed_out and len(failed) > 1 and not self.project.cancelled:
            for i in failed:
                attempts.suspected(i)
            hung += failed
            return []
        if error is not None and len(failed) > 1 and budget[0] > 0 and not self.project.cancelled:
            half = len(failed) // 2
            return (self._halving(failed[:half], run, done, attempts, kind, ledger_kind, budget, hung) +
                    self._halving(failed[half:], run, done, attempts, kind, ledger_kind, budget, hung))
        self._charge(failed, error, attempts, kind, ledger_kind)
        return failed

    def _run(self, items, run, done, attempts):
        """One run of `run(items)`: (the items done() does not list afterwards, the error or None,
        whether it timed out). What is done is forgiven."""
        error, timed_out = None, False
        try:
            run(items)
        except ProjectError as e:
            if getattr(e, "out_of_time", False):
                raise  # the finish's budget is spent: no item's fault, and nothing more is tried
            error, timed_out = str(e), getattr(e, "timed_out", False)
            self.error(error)
        now = done()
        for i in items:
            if i in now:
                attempts.succeeded(i)
        # A pair handed over to wait for a run of COLMAP's matcher has neither failed nor succeeded.
        return [i for i in items if i not in now and i not in self.fallback_waiting], error, timed_out

    def _charge(self, failed, error, attempts, kind, ledger_kind):
        """A failure for each item (its own reason where the backend knows it); an item that
        reaches ~max_attempts is given up, ledgered and logged. A run the shutdown cancelled
        charges nobody."""
        if error is not None and self.project.cancelled:
            return
        default = error or ("no features were extracted (an image that cannot be read?)" if kind == "image"
                            else "no two-view geometry was written for it")
        errors = getattr(self.backend, "errors", None) or {}
        for i in failed:
            reason = errors.get(i, default)
            if attempts.failed(i, reason):
                label = i if isinstance(i, str) else "%s %s" % i
                self.project.ledger(ledger_kind, [label])
                self.error("%s %s skipped after %d attempts: %s" % (kind, label, attempts.failures[i], reason))

    # -- features ----------------------------------------------------------------------------
    def extract(self, keyframes):
        """Features of the keyframes whose images are there, that have none and are due.
        Returns how many were tried."""
        changes = self.seen["extract"].scan(keyframes)
        if changes.reset:
            self.unextracted = {}
        for k in changes.keyframes:
            self.unextracted[k.name] = k
        try:
            self.backend.register(changes.keyframes)  # the moved ones too: the backend keeps poses
        except Exception:
            self.seen["extract"].forget()  # the next batch registers every keyframe again
            raise
        done = self.backend.extracted()
        waiting = self.unextracted
        for name in [n for n in waiting if n in done]:
            del waiting[name]
        todo = [k for k in waiting.values() if self.backend.has_image(k.name) and self.images.due(k.name)]
        self.status.update(keyframes=len(keyframes), images_extracted=len(done), images_waiting=len(todo))
        if not todo:
            return 0
        by_name = {k.name: k for k in todo}
        self._attempt([k.name for k in todo], lambda names: self.backend.extract([by_name[n] for n in names]),
                      lambda: self.backend.extracted(refresh=list(by_name)), self.images, "image", "skipped-image")
        done = self.backend.extracted()
        for name in [n for n in by_name if n in done]:
            del waiting[name]
        for warning in getattr(self.backend, "warnings", None) or []:
            self.log("warn", warning)
        return len(todo)

    # -- matches -----------------------------------------------------------------------------
    def taken_back(self, pairs):
        """The node took these announced pairs (names) back: those already matched were matched
        for nothing, and DIR/ledger.txt says when (`taken-back`, beside when each was `matched`).
        Returns how many."""
        matched = self.backend.matched()
        wasted = [p for p in pairs if p in matched]
        self.project.ledger("taken-back", ["%s %s" % p for p in wasted])
        return len(wasted)

    def announce(self, changes):
        """The announced pairs (names, sorted within) changed: stream.AnnouncedChanges, against
        what this was told before (PairStream.take_changes, each in turn). Only sets change: a
        caller that takes the changes from the stream hands them over here first, so that a
        batch that fails afterwards loses none of them."""
        self.wanted.apply(changes)

    def _announced(self, pairs):
        """match()'s and wanted_pairs()'s `pairs`: None (no change), AnnouncedChanges (the
        changes), or any other collection of pairs (names): the announced set, whole."""
        if pairs is None:
            return
        if isinstance(pairs, AnnouncedChanges):
            self.wanted.apply(pairs)
        else:
            self.wanted.replace(pairs)

    def _wanted_beside(self, pair):
        """Whether a pair is wanted besides being announced: a continuity or loop pair."""
        return (self.continuity and pair in self.chain.pairs) or (self.loops is not None and pair in self.loops.pairs)

    def _beside(self):
        """The sets of pairs wanted beside the announced ones, whole."""
        return ([self.chain.pairs] if self.continuity else []) + ([self.loops.pairs] if self.loops is not None else [])

    def _refresh_wanted(self, keyframes, wanted):
        """The continuity chain and the loop candidates brought up to date with the keyframes
        that changed since the last call; their new pairs join the backlog of `wanted` and of
        the batches' own (self.wanted), which are built again from everything wanted when the
        chain is (another session)."""
        states = [self.wanted] if wanted is self.wanted else [self.wanted, wanted]
        changes = self.seen["wanted"].scan(keyframes)
        try:
            new, rebuild = [], changes.reset or self._rebuild_wanted
            if self.continuity:
                added = None if changes.reset else self.chain.extend(changes.new)
                if added is None:
                    self.chain.rebuild(keyframes)
                    rebuild = True
                else:
                    new += added
            if self.loops is not None:
                new += self.loops.update(changes.keyframes, wanted)  # the new keyframes' pairs across a revisit
            for state in states:
                if rebuild:
                    state.rebuild(self._beside())
                else:
                    state.want(new)
            self._rebuild_wanted = False
        except Exception:
            self.seen["wanted"].forget()  # the next batch looks at every keyframe again
            self._rebuild_wanted = True   # and builds the backlog again from everything wanted
            raise

    def wanted_pairs(self, keyframes, pairs=None):
        """Every wanted pair (names), a set of its own: the announced pairs (`pairs` as match()
        takes them) plus, with continuity, each keyframe with the one before, and with loops the
        pairs across revisits proposed so far (matching/loops.py). The whole session: a batch
        does not ask for it (match() keeps the backlog from what changed)."""
        self._announced(pairs)
        self._refresh_wanted(keyframes, self.wanted)
        return self.wanted.everything(self._beside())

    def match(self, keyframes, pairs=None, limit=None, quiet=False, paused=None):
        """Matches at most `limit` (~max_batch_pairs) of the wanted pairs not matched yet whose
        images have features and that are due; True when more are waiting. `pairs`: the
        announced pairs (names): their changes since the last call (stream.AnnouncedChanges, as
        announce() takes them), None when they did not change (or were handed to announce()),
        or the whole announced set (any other collection of pairs: compared with the one held).

        While the recording goes on, at most ~max_backlog of the waiting pairs are considered
        (the oldest by name; the rest are counted in `deferred`); the finish (match_all) takes
        every one of them: ~max_backlog bounds what a batch looks at, never what the model gets.
        The pairs the poses cannot match wait for a run of COLMAP's matcher with others
        (FALLBACK_RUN_PAIRS, FALLBACK_MAX_WAIT), for `quiet` (no keyframe for a while: the
        finish may be near) or for the finish. The announced pairs within ~match_delay wait for
        `paused` (the recording paused or ended; `quiet` when not given) or for the finish:
        keyframes alone pause whenever the camera walks where it has been, while the node goes on
        taking pairs back (a 30-minute walk on odometry had 1,004 pauses of keyframes of 0.5 s or
        more)."""
        self._announced(pairs)
        return self._match(keyframes, self.wanted, self.max_batch_pairs if limit is None else limit,
                           self.max_backlog, flush=quiet, flush_delayed=quiet if paused is None else paused)

    def _match(self, keyframes, wanted, limit, max_backlog=None, flush=True, flush_delayed=True):
        """One run over `wanted` (a WantedPairs: the batches' own, or the finish's): its work is
        that of the keyframes and pairs that changed and of the backlog, not of the session."""
        matched = self.backend.matched()
        self._refresh_wanted(keyframes, wanted)
        for p in [p for p in self.fallback_waiting if p not in wanted or p in matched]:
            del self.fallback_waiting[p]  # no longer wanted (or matched meanwhile): not matched for nothing
        have = self.backend.extracted()
        backlog = [p for p in wanted.waiting(matched)
                   if p[0] in have and p[1] in have and not self.pairs.given_up(p)]
        self.backlog_max = max(self.backlog_max, len(backlog))
        self.backlog_before = len(backlog)  # before this run
        settled = self._settled(backlog, flush_delayed)
        self.status.update(backlog_pairs=len(backlog), pairs_matched=len(matched))
        if max_backlog is not None and len(backlog) > max_backlog:
            self.deferred = max(self.deferred, len(backlog) - max_backlog)
            self.log("warn", "more pairs wait than ~max_backlog (%d): the rest are matched at the finish "
                     "(/diagnostics: backlog pairs)" % max_backlog)  # one text: throttled as one
            backlog = backlog[:max_backlog]
        due = [p for p in backlog if self.pairs.due(p) and p not in self.fallback_waiting
               and (settled is None or p in settled)]
        batch = due[:limit]
        if batch:
            run = self.backend.match
            if self.fallback_batched:
                run = lambda items: self.backend.match(items, defer_fallback=self._fallback_waits)  # noqa: E731
            self._attempt(batch, run, lambda: self.backend.matched(refresh=batch), self.pairs, "pair", "skipped-pair")
        fallback_run = self._fallback_due(flush)
        if fallback_run:
            self._attempt(fallback_run, self.backend.match_fallback, lambda: self.backend.matched(refresh=fallback_run),
                          self.pairs, "pair", "skipped-pair")
        done = len((set(batch) | set(fallback_run)) & self.backend.matched()) if batch or fallback_run else 0
        self.due_left = len(due) - len(batch)
        self.status.update(backlog_pairs=len(backlog) - done, pairs_matched=len(matched) + done,
                           fallback_waiting=len(self.fallback_waiting))
        return self.due_left > 0

    def _settled(self, backlog, flush):
        """The pairs of the backlog that may be matched now, as a set, or None for all of them:
        an announced pair once a batch wanted it ~match_delay ago, a continuity or loop pair at
        once, and every one when flushing. Each pair's time is kept while it waits."""
        if self.match_delay <= 0:
            return None
        now = self.now()
        since = {p: self.wanted_since.get(p, now) for p in backlog}
        self.wanted_since = since  # a pair matched or taken back is forgotten
        if flush:
            return None
        chain = self.chain.pairs if self.continuity else ()
        loops = self.loops.pairs if self.loops is not None else ()
        return {p for p, t in since.items() if now - t >= self.match_delay or p in chain or p in loops}

    def _fallback_waits(self, pairs):
        now = self.now()
        for p in pairs:
            self.fallback_waiting.setdefault(p, now)

    def _fallback_due(self, flush):
        """The waiting fallbacks, when their run is due (and no longer waiting then), else []."""
        waiting = self.fallback_waiting
        if not waiting or not (flush or len(waiting) >= FALLBACK_RUN_PAIRS or
                               self.now() - min(waiting.values()) >= FALLBACK_MAX_WAIT):
            return []
        run = sorted(waiting)
        waiting.clear()
        return run

    def match_all(self, keyframes, pairs, batch=FINISH_BATCH_PAIRS, progress=None):
        """Every wanted pair that is due and whose images have features, in runs of `batch` pairs
        (each halved where it fails, as in a batch), until none is left: the finish's matching,
        whatever ~max_backlog is. A pair that fails is not due again until its wait is over, so
        this ends. progress(done, total): after each run. Returns how many runs were made.
        `pairs`: the announced pairs (names), whole: the finish's, kept apart from the batches'
        (the pair stream's changes go on from where the batches took them)."""
        wanted = WantedPairs(self._wanted_beside)
        wanted.replace(pairs)
        wanted.rebuild(self._beside())  # the chain and loops so far; _match adds what the keyframes bring
        runs = 0
        total = None
        while not self.project.cancelled:
            more = self._match(keyframes, wanted, batch)
            if total is None:
                total = self.backlog_before
            runs += 1
            if progress is not None:
                progress(total - self.status.get("backlog_pairs", 0), total)
            if not more:
                break
        return runs

    # -- the live model ----------------------------------------------------------------------
    def feed_model(self, keyframes, final=False):
        """The live model takes the keyframes' poses (new ones, and corrected ones) and the
        verified pairs it does not have yet, and triangulates the tracks that changed; returns
        how many. Also after a restart: the database's pairs all come in once."""
        from ..colmap.model import CAMERA_MODELS
        m = self.model
        cat = self.project.catalogue()  # what the database holds, in memory: no table is read whole
        ids, cams, cameras, with_features = cat.ids, cat.image_cameras, cat.cameras, cat.with_features
        self.unfed_pairs.extend(cat.take_new_verified())
        check = getattr(self.project, "check_deadline", lambda stage: None)
        with self.project.db() as d:
            fed, unfed = self.fed_keyframes, self.unfed
            changes = self.seen["model"].scan(keyframes)
            if changes.reset:
                unfed.clear()
            for k in changes.keyframes:
                if fed.get(k.name) is not k:
                    unfed[k.name] = k  # a keyframe object fed before has not changed: not looked at
            for k in list(unfed.values()):
                check("triangulation")
                iid = ids.get(k.name)
                if iid is None:
                    continue
                pose = (k.position, k.orientation)
                known = m.images.get(iid)
                if known is not None and self.fed_poses.get(k.name) == pose and (
                        len(known.keypoints) or k.name not in with_features):
                    if len(known.keypoints) or k.name in with_features:
                        fed[k.name] = k
                        del unfed[k.name]
                    continue
                q, t = self.pose_of(k, iid)
                mid, w, h, params = cameras[cams[iid]]
                keypoints = d.keypoints(iid) if (known is None or not len(known.keypoints)) else known.keypoints
                m.add_image(iid, k.name, cams[iid], (CAMERA_MODELS[mid][0], w, h, params), q, t, keypoints)
                self.fed_poses[k.name] = pose
                if len(m.images[iid].keypoints) or k.name in with_features:
                    fed[k.name] = k  # complete: looked at again only when a new object comes (a new pose)
                    del unfed[k.name]
            # The pairs that verified since the last update; one whose image the model does not
            # have yet (its keyframe not announced, or no features) waits for it.
            waiting = []
            for n, (a, b) in enumerate(self.unfed_pairs):
                if (a, b) in m.matched_pairs:
                    continue
                try:
                    check("triangulation")
                except ProjectError:
                    self.unfed_pairs = waiting + self.unfed_pairs[n:]  # they wait for the next time
                    raise
                if a in m.images and b in m.images:
                    m.add_matches(a, b, d.matches(a, b, "two_view_geometries"))
                else:
                    waiting.append((a, b))
            self.unfed_pairs = waiting
        check("triangulation")
        changed = m.update(final=final)
        self.status.update(points=len(m.points), tracks=len(m.members))
        return changed

    def behind(self):
        """Whether the matching fell behind: more than BEHIND_BATCHES batches' worth of pairs were
        due and left for later by the last batch (a burst of continuity and loop pairs is less;
        the pairs within ~match_delay are not due yet)."""
        return self.due_left > BEHIND_BATCHES * self.max_batch_pairs

    def refine_in_background(self):
        """The bridge's worker loop, after a batch: a refinement that runs beside the matching
        (refinement/local.py) polls its run and starts the next; True while one runs. While the
        matching is behind (behind()) the run under way yields the CPU and none starts."""
        step = getattr(self.refinement, "step", None)
        return bool(step(behind=self.behind())) if step is not None and self.model is not None else False

    def skipped(self, all_failed=False):
        """What was given up (with all_failed: also what failed and was not retried yet)."""
        images, pairs = self.images.skipped(all_failed), self.pairs.skipped(all_failed)
        return {"images": images, "pairs": [dict(s, item="%s %s" % s["item"]) for s in pairs]}

    # -- the model ---------------------------------------------------------------------------
    def lost_pairs(self, wanted, matched, extracted, missing, stopped=None):
        """[{'pair': 'a b', 'reason'}] of the wanted pairs that were not matched at all (a pair
        matched and found not to verify is not lost: COLMAP's verification said no), each with
        why: an image missing or without features, the pair given up after its attempts, or not
        tried (the work was cancelled or ran out of time)."""
        missing = set(missing)
        out = []
        for pair in sorted(set(wanted) - set(matched)):
            reason = None
            for name in pair:
                if name in missing:
                    reason = "the image %s never arrived" % name
                elif name not in extracted:
                    error = self.images.errors.get(name)
                    reason = "the image %s has no features%s" % (name, ": " + error if error else "")
                if reason:
                    break
            if reason is None:
                error = self.pairs.errors.get(pair)
                if error is not None:
                    reason = "failed %d time(s): %s" % (self.pairs.failures.get(pair, 0), error)
                elif stopped:
                    reason = "not tried: %s" % stopped
                elif self.project.cancelled:
                    reason = "not tried: the work was cancelled"
                else:
                    reason = "not tried"
            out.append({"pair": "%s %s" % pair, "reason": reason})
        return out

    def build_model(self, keyframes, final_pairs, model="known_poses", seed=0, progress=None):
        """What is left of `final_pairs` (names) extracted and matched, then the model; returns
        the report's model part. The bridge's finish and colmap_from_selection share it.
        Every wanted pair is matched (match_all); one that is not in the model is listed in
        pairs_lost with its reason. progress(stage, done, total): as the matching goes.
        Items given up are left out and listed; a keyframe without features or image is not in
        the model, and the report says which."""
        import os
        from ..colmap import model as colmap_model
        from .. import geometry
        from ..evaluation.trajectory import ate_rmse
        project = self.project
        final = sorted({pair_of(*p) for p in final_pairs})
        extra = sorted(set(continuity_pairs(keyframes)) - set(final)) if self.continuity else []
        loops = set()
        if self.loops is not None:
            self.wanted.want(self.loops.update(keyframes, set(final) | set(extra)))  # batches after it want them too
            loops = self.loops.pairs - set(final) - set(extra)
        durable.write_atomically(os.path.join(project.root, "pairs.txt"),  # COLMAP's match list
                                 "".join("%s %s\n" % p for p in final))
        # Everything due now, in one run each (halved where a run fails): the finish does not
        # wait for backoffs, and what fails now is reported as skipped.
        for attempts in (self.images, self.pairs):
            attempts.not_before.clear()
        import time
        phases, t0 = {}, time.monotonic()
        made = None  # the live model written, when it is
        statistics = None  # the model's (Model.statistics), when known without reading it back
        # Out of time (the shutdown's budget, project.deadline): what is done so far is the
        # model, written as it stands, unrefined, and report.json says so (complete: false).
        incomplete = None
        try:
            self.extract(keyframes)
            phases["extraction"], t0 = time.monotonic() - t0, time.monotonic()
            self.match_all(keyframes, final, progress=(lambda done, total: progress("matching", done, total))
                           if progress else None)
        except ProjectError as e:
            if not e.out_of_time:
                raise
            incomplete = str(e)
        phases["matching"], t0 = time.monotonic() - t0, time.monotonic()
        missing = [k.name for k in keyframes if not project.has_image(k.name)]
        extracted = project.extracted()
        matched = set(project.matched())
        with project.db() as d:
            featureless = sorted(d.images_without_keypoints())
        wanted = set(final) | set(extra) | loops
        inliers = project.inlier_counts()
        lost = self.lost_pairs(wanted, matched, extracted, missing, stopped=incomplete)
        if lost:
            self.error("%d of %d wanted pairs are not in the model (report.json: pairs_lost), e.g. %s: %s"
                       % (len(lost), len(wanted), lost[0]["pair"], lost[0]["reason"]))
        out = {"keyframes": len(keyframes), "images_missing": missing,
               "images_without_features": [k.name for k in keyframes if k.name not in extracted and k.name not in missing],
               "images_with_no_features": featureless,
               "final_pairs": len(final), "continuity_pairs": len(extra), "loop_pairs": len(loops),
               "loop_pairs_verified": sum(1 for p in loops if inliers.get(p, 0) > 0),
               "loop_pairs_from_revisits": len(loops & self.loops.registered) if self.loops is not None else 0,
               "pairs_matched": len(matched),
               "final_pairs_matched": len(set(final) & matched), "pairs_wasted": len(matched - wanted),
               "pairs_wanted": len(wanted), "pairs_lost": lost,
               "pairs_not_verified": sum(1 for p, n in inliers.items() if p in wanted and n == 0),
               "pairs_verified": project.verified_count(), "model": model, "skipped": self.skipped(all_failed=True)}
        if model == "mapper":
            path = project.mapper_model(seed)
            mapped = colmap_model.read_model(path).image_by_name()
            by_name = {k.name: k for k in keyframes}
            common = [n for n in mapped if n in by_name]
            out["ate_rmse"] = ate_rmse([geometry.centre_of(mapped[n].qvec, mapped[n].tvec) for n in common],
                                       [by_name[n].position for n in common])
            out["ate_images"] = len(common)
        else:
            have = [k for k in keyframes if k.name not in missing]
            if len(have) < 2:
                raise ProjectError("%d of %d keyframes have their image in %s: a model needs at least 2 "
                                   "(the node keeps earlier keyframes' images only with ~save_keyframe_images)"
                                   % (len(have), len(keyframes), project.images))
            if self.model is not None:
                if incomplete is None:
                    try:
                        with self.clock.measure("triangulation", 1):
                            out["tracks_triangulated_at_finish"] = self.feed_model(keyframes, final=True)
                    except ProjectError as e:
                        if not e.out_of_time:
                            raise
                        incomplete = str(e)
                phases["triangulation"], t0 = time.monotonic() - t0, time.monotonic()
                with project.db() as d:
                    ids = d.image_ids()
                made = self.model.to_model([ids[k.name] for k in have if k.name in ids])
                path = project.write_model(made)
                phases["writing"], t0 = time.monotonic() - t0, time.monotonic()
                if out["pairs_verified"] == 0:
                    out["model_error"] = "no pair verified: the model holds the keyframes' poses and no points"
                    self.error(out["model_error"])
            elif out["pairs_verified"] == 0:
                out["model_error"] = "no pair verified: the model holds the keyframes' poses and no points"
                self.error(out["model_error"])
                path = project.poses_only_model(have)
            else:
                try:
                    path = project.known_pose_model(have)
                except ProjectError as e:
                    if project.deadline is not None or project.cancelled:
                        raise  # out of time at shutdown: the model written before stays
                    out["model_error"] = "%s: the model holds the keyframes' poses and no points" % e
                    self.error(out["model_error"])
                    path = project.poses_only_model(have)
        out["complete"] = incomplete is None
        if incomplete is not None:
            out["incomplete"] = ("%s: the model is the live model as it stood (the keyframes and points it had), "
                                 "not refined" % incomplete)
            self.error(out["incomplete"])
        elif self.refinement is not None and model != "mapper" and "model_error" not in out:
            # issue 29: sparse/0 refined (the live model's union-find holds every matched observation)
            matched = len(self.model.parent) if made is not None else 0
            out["refinement"] = self.refinement.apply(project, path, made, matched)
            # The statistics are the refined model's: from refine_model's report when it has
            # them, else read from sparse/0 (unless the refinement failed: then it is `made`).
            stats = out["refinement"].pop("statistics", None)
            if out["refinement"].get("status") != "error":
                made, statistics = None, stats
            phases["refinement"], t0 = time.monotonic() - t0, time.monotonic()
        out["model_path"] = path
        if statistics is None:
            statistics = (made if made is not None else colmap_model.read_model(path)).statistics()
        out.update(statistics)
        phases["statistics"] = time.monotonic() - t0
        out["finish_phases"] = {k: round(v, 3) for k, v in phases.items()}
        out["waste_ratio"] = out["pairs_wasted"] / out["pairs_matched"] if out["pairs_matched"] else 0.0
        return out
