"""The refinement while the recording goes on (issue 34), as a SLAM system's local mapping does.

One global adjustment in the finish, within its budget (refiner.FINISH_MAX_SECONDS), made 1-4
Ceres iterations on 1,000-3,000 keyframes: a long session kept its drift (0.99x on a 5-minute
walk) while a short one was refined to convergence. Here the refinement runs beside the matching,
on what the live model (live/model.py) holds:

  - **local**: once `every` keyframes with points were never refined, a window of them (the
    oldest such, `size` at most, filled up with the refined keyframes just before them) is free;
    held are the keyframes that see the same points (`max_fixed`, the most shared first), those
    with a verified pair with the window (across a revisit the drift keeps them from sharing a
    point at the live model's 3 px, and their matches are what corrects it) and the window's
    neighbours in keyframe order (so that every SLAM motion prior touching a free keyframe is
    between consecutive keyframes, refine_model's chain); the problem is cropped to them: the
    points the window sees and the matches with a free side (refine_model triangulates them
    anew, at 9 px first);
  - **global**: once the verified pairs grew by `global_growth` (a quarter) since the last one,
    the whole model, every keyframe free (aligned to the poses it started from): what pulls
    the drift back along a loop; its poses alone are taken, so it is given at most
    `global_matches` (100) of each pair's matches, spread over the pair. Windows alone hold the
    keyframes before them where they were
    and leave the correction of a revisit at their edge (measured on the built-in walk with
    the odometry stand-in: 18.0 mm against 3.2 mm for a full refinement);
  - **finish** (`apply`, what LiveWork.build_model calls): the keyframes that changed since a
    refinement of the whole model last had them (new ones, a node pose that moved, a verified
    pair it did not have) free, everything they see held; all of them free (a full refinement,
    as before, from the poses the runs reached) when more than half the model changed or a
    revisit's pair (between keyframes more than two windows apart) came since.

Each run is refine_model as a child process (niced with the bridge, one thread), started and
polled from the bridge's worker loop (`step`), so matching goes on while it runs. The runs are
budgeted: their CPU (the child's, measured by wait4, and the crop's in Python) stays within
`cpu_share` of a core on average over the session, `local_fraction` of it for the windows and
the rest for the whole model; a run may overspend its part, and the next of its kind waits until
that is paid back.

The refined poses go into the live model (its tracks are triangulated again at them, so its
points follow). A keyframe not refined yet takes the correction of the nearest refined keyframe
before it (its node pose moved rigidly with it: the SLAM motion since is kept), so new keyframes
arrive where the refined model continues. `sparse/unrefined` stays the model at the node's poses:
the live model's points carried to them by each point's first keyframe (`at_node_poses`).
"""
import bisect
import os
import shutil
import tempfile
import time

import numpy as np

from .. import geometry
from ..colmap import durable, model as colmap_model
from ..colmap.database import DatabaseError
from ..colmap.project import ProjectError
from . import refiner


# -- the window ----------------------------------------------------------------------------
def choose_window(order, observed, refined, covisible, kind, changed=(), size=20, max_fixed=60, partners=None):
    """(free, fixed): the image ids of one refinement, free ones in `order`.

    order: every image id, oldest first (keyframe order). observed: ids with points. refined:
    ids refined since they last changed. covisible(free ids) -> {image id: points shared with
    them}. changed: ids whose pose or pairs changed since they were last refined (kind
    'changed'). kind: 'local' (the oldest `size` observed ids never refined, filled up to `size`
    with the observed ids just before them), 'changed' (every id in `changed`), or 'global'
    (every id, nothing held). Held: up to `max_fixed` of the ids that share points with the free
    ones (the most first; every one for 'changed'), every id partners(free ids) names (those with
    a verified pair with a free one: across a revisit the drift keeps them from sharing points
    at the live model's 3 px, and their matches are what corrects it), and each free id's
    neighbours in `order`."""
    if kind == "global":
        return list(order), []
    observed, refined = set(observed), set(refined)
    if kind == "local":
        new = [i for i in order if i in observed and i not in refined][:size]
        if not new:
            return [], []
        first = order.index(new[0])
        before = [i for i in order[:first] if i in observed][::-1][:max(0, size - len(new))]
        free = sorted(set(new) | set(before), key=order.index)
    elif kind == "changed":
        changed = set(changed)
        free = [i for i in order if i in changed]
    else:
        raise ValueError("kind: local, changed or global, not %r" % kind)
    if not free:
        return [], []
    free_set = set(free)
    shared = sorted(((n, i) for i, n in covisible(free_set).items() if i not in free_set and n > 0),
                    key=lambda x: (-x[0], x[1]))
    fixed = {i for _, i in (shared if kind == "changed" else shared[:max_fixed])}
    if partners is not None:
        fixed |= set(partners(free_set)) - free_set
    position = {i: q for q, i in enumerate(order)}
    for i in free:
        q = position[i]
        for j in (q - 1, q + 1):
            if 0 <= j < len(order) and order[j] not in free_set:
                fixed.add(order[j])
    return free, sorted(fixed, key=position.get)


def covisible_in(live, free):
    """{image id: points of the live model it shares with the `free` images}."""
    counts = {}
    roots = set()
    for i in free:
        roots |= live.by_image.get(i, set())
    for root in roots:
        point = live.points.get(root)
        if point is None or not any(i in free for i in point[2]):
            continue
        for i in point[2]:
            counts[i] = counts.get(i, 0) + 1
    return counts


def partners_in(live, free):
    """The images with a verified pair with one of the `free` images."""
    out = set()
    for a, b in live.matched_pairs:
        if a in free:
            out.add(b)
        elif b in free:
            out.add(a)
    return out


def crop(live, free, fixed):
    """The live model cropped to a window: the images `free` and `fixed` at their poses, and the
    points with an observation in a free image (observations in other images left out, points
    left with fewer than two dropped)."""
    return live.to_model(set(free) | set(fixed), seen_by=free)


def window_pairs(live, free, fixed):
    """The verified pairs (image ids) of the crop with a free side."""
    free, keep = set(free), set(free) | set(fixed)
    return sorted(p for p in live.matched_pairs if p[0] in keep and p[1] in keep and (p[0] in free or p[1] in free))


# -- poses ---------------------------------------------------------------------------------
def corrected(node, refined_pose, node_then):
    """COLMAP's (qvec, tvec) of the node pose `node` ((centre, (w, x, y, z)) camera-to-world)
    moved by the rigid correction that took `node_then` to `refined_pose` ((qvec, tvec))."""
    r_then = geometry.rotation_of(node_then[1])                       # camera -> world, node
    r_ref = geometry.rotation_of(refined_pose[0]).T                   # camera -> world, refined
    c_ref = -r_ref @ np.asarray(refined_pose[1], float)
    g = r_ref @ r_then.T                                              # the world's correction
    gt = c_ref - g @ np.asarray(node_then[0], float)
    r_new = g @ geometry.rotation_of(node[1])
    c_new = g @ np.asarray(node[0], float) + gt
    r_wc = r_new.T
    return geometry.quaternion_of(r_wc), tuple(float(v) for v in -r_wc @ c_new)


def at_node_poses(model, node_poses, max_error=4.0):
    """`model` (colmap.model.Model at refined poses) with every image at its node pose
    ({image id: (qvec, tvec)}) and each point carried by its first image's correction (it keeps
    its place in that image); observations that then reproject further than `max_error` px or
    lie behind their camera are dropped, and points left with fewer than two. What a model at
    the node's poses holds, without triangulating the session again."""
    out = colmap_model.Model(dict(model.cameras))
    ids = sorted(model.images)
    index = {iid: q for q, iid in enumerate(ids)}
    r_node, t_node, r_now, t_now, k = [], [], [], [], []
    for iid in ids:
        im = model.images[iid]
        q, t = node_poses.get(iid, (im.qvec, im.tvec))
        r_node.append(geometry.rotation_of(q))
        t_node.append(np.asarray(t, float))
        r_now.append(geometry.rotation_of(im.qvec))
        t_now.append(np.asarray(im.tvec, float))
        k.append(model.cameras[im.camera_id].params[:4])
        out.images[iid] = colmap_model.Image(iid, q, t, im.camera_id, im.name, im.xys,
                                             np.full(len(im.xys), -1, np.int64))
    if not model.points:
        return out
    r_node, t_node, r_now, t_now, k = (np.array(a) for a in (r_node, t_node, r_now, t_now, k))
    pids = sorted(model.points)
    pts = [model.points[pid] for pid in pids]
    xyz = np.array([p.xyz for p in pts])
    first = np.array([index[int(p.image_ids[0])] for p in pts])
    # x in the first image's camera, then back to the world through its node pose
    cam = np.einsum("nij,nj->ni", r_now[first], xyz) + t_now[first]
    x = np.einsum("nji,nj->ni", r_node[first], cam - t_node[first])
    lengths = np.array([len(p.image_ids) for p in pts])
    owner = np.repeat(np.arange(len(pts)), lengths)
    img = np.array([index[int(i)] for p in pts for i in p.image_ids])
    kp = np.concatenate([p.point2D_idxs for p in pts]).astype(np.int64)
    xy = np.array([model.images[ids[i]].xys[j] for i, j in zip(img, kp)])
    pc = np.einsum("nij,nj->ni", r_node[img], x[owner]) + t_node[img]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([k[img, 0] * pc[:, 0] / pc[:, 2] + k[img, 2], k[img, 1] * pc[:, 1] / pc[:, 2] + k[img, 3]], 1)
        errors = np.linalg.norm(uv - xy, axis=1)
    good = (pc[:, 2] > 0) & (errors <= max_error)
    kept = np.bincount(owner[good], minlength=len(pts))
    sums = np.bincount(owner[good], weights=errors[good], minlength=len(pts))
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    for q, pid in enumerate(pids):
        if kept[q] < 2:
            continue
        sel = slice(starts[q], starts[q] + lengths[q])
        mask = good[sel]
        image_ids = [ids[i] for i in img[sel][mask]]
        idxs = kp[sel][mask]
        out.points[pid] = colmap_model.Point3D(pid, x[q], pts[q].rgb, float(sums[q] / kept[q]), image_ids, idxs)
        for iid, j in zip(image_ids, idxs):
            out.images[iid].point3D_ids[j] = pid
    return out


def node_poses(work):
    """{image id: (centre, orientation)} of the node, for a LiveWork's live model's images."""
    fed = work.fed_poses
    return {iid: fed[im.name] for iid, im in work.model.images.items() if im.name in fed}


def same_pose(a, b, tolerance=1e-6):
    """Whether node poses a and b ((centre, (w, x, y, z)), or None) are the same within
    `tolerance` [m, and in each quaternion component]: a pose sent again (the stream's `full`
    resync, the node's final selection) may differ from the first in its last bits."""
    if a is None or b is None:
        return a is b
    if a == b:
        return True
    qa, qb = np.asarray(a[1], float), np.asarray(b[1], float)
    if float(np.dot(qa, qb)) < 0:
        qb = -qb
    return bool(np.max(np.abs(np.asarray(a[0], float) - np.asarray(b[0], float))) <= tolerance
                and np.max(np.abs(qa - qb)) <= tolerance)


def predicted(ids, taken, iid, node):
    """COLMAP's (qvec, tvec) for image `iid` at node pose `node`: moved by the correction of the
    nearest image before it in `ids` (sorted; after it, for the first ones), whose `taken` entry
    is ((qvec, tvec) refined, its node pose then)."""
    q = bisect.bisect_left(ids, iid)
    near = ids[q - 1] if q > 0 else ids[0]
    refined_pose, then = taken(near)
    return corrected(node, refined_pose, then)


# How much nicer a run under way is made while the bridge's matching is behind (_Run.yield_cpu).
# A run at 7,500 keyframes takes 11 s of CPU in 22 s: on a machine that SLAM keeps busy it took the
# bridge's CPU for the last 30 s of a 30-minute walk, whose batches then came every 2.5 s instead
# of every 0.2, and left its finish 379 pairs to match (ready 11.9 s after the bag, not 8.3).
YIELD_NICE = 10


class _Run:
    """One refine_model child: what it was given and what it is."""

    def __init__(self, kind, free, fixed, folder, proc, node, pairs, cpu, max_seconds, timeout):
        self.kind, self.free, self.fixed, self.folder, self.proc = kind, free, fixed, folder, proc
        self.node, self.pairs, self.cpu = node, pairs, cpu
        self.started, self.max_seconds, self.timeout = time.monotonic(), max_seconds, timeout
        self.rusage = None
        self.status = None
        self.yielded = False  # made nicer (yield_cpu)

    def yield_cpu(self, nice=YIELD_NICE):
        """Makes the child `nice` nicer than it is, every thread of it, once (a process cannot be
        made less nice again without privileges): the bridge's own matching, which fell behind,
        comes first; the run goes on with what the machine leaves. True when it was made nicer
        now."""
        if self.yielded or self.status is not None:
            return False
        self.yielded = True
        pid = self.proc.pid
        try:
            threads = [int(t) for t in os.listdir("/proc/%d/task" % pid)]
        except OSError:
            threads = [pid]
        done = False
        for tid in threads:  # Linux's niceness is a thread's: each of them
            try:
                os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + nice))
                done = True
            except OSError:
                pass  # it ended meanwhile
        return done

    def poll(self):
        """True once the child ended (its CPU in self.rusage)."""
        if self.status is not None:
            return True
        pid, status, rusage = os.wait4(self.proc.pid, os.WNOHANG)
        if pid == 0:
            return False
        self.status, self.rusage = os.waitstatus_to_exitcode(status), rusage
        self.proc.returncode = self.status
        return True

    def kill(self):
        if self.status is None:
            refiner.Colmap._kill(self.proc)
            self.status = self.proc.returncode if self.proc.returncode is not None else -9
        shutil.rmtree(self.folder, ignore_errors=True)

    def overdue(self):
        """Still running past its timeout (a hung tool: refine_model stops itself at its
        --max-seconds): killed here. False while it runs within it or once it ended."""
        if self.poll() or time.monotonic() - self.started <= self.timeout:
            return False
        self.kill()
        return True

    def wait(self, seconds):
        """Waits at most `seconds` for the child to end; kills it when it would take longer.
        True when it ended by itself."""
        end = time.monotonic() + seconds
        while not self.poll() and time.monotonic() < end:
            time.sleep(0.02)
        if self.poll():
            return True
        self.kill()
        return False


class LocalRefinement:
    """The refinement of a LiveWork's live model while the recording goes on (the module's
    docstring), and the finish's refinement of what changed since (`apply`, in place of
    ModelRefinement's, whose options, tool and log it takes)."""

    def __init__(self, finish, size=20, every=10, max_fixed=60, cpu_share=0.25, local_fraction=0.3,
                 local_seconds=3.0, global_seconds=120.0, global_growth=0.25, global_matches=100,
                 clock=time.monotonic):
        self.finish_refinement = finish
        self.size, self.every, self.max_fixed = int(size), int(every), int(max_fixed)
        self.cpu_share, self.local_seconds, self.global_seconds = float(cpu_share), float(local_seconds), float(global_seconds)
        self.global_growth, self.local_fraction = float(global_growth), float(local_fraction)
        self.global_matches = int(global_matches)
        self.clock = clock
        self.work = None
        self.refined = {}        # image id -> (qvec, tvec refined, the node pose then)
        self.refined_ids = []    # sorted
        self.used_pairs = set()  # verified pairs (image ids) a refinement of the whole model had
        self.covered = {}        # image id -> its node pose when a refinement of the whole model took it
        self.running = None
        self.started_at = None
        self.cpu_seconds = 0.0
        self.cpu_by_kind = {"local": 0.0, "global": 0.0}
        self.runs = {"local": 0, "global": 0}
        self.failures = 0
        self.global_pairs = 0    # matched pairs when the last global run started
        self.history = []        # per applied run: kind, free, fixed, cpu, status, seconds
        self.log = finish.log if finish is not None else (lambda level, text: None)

    # -- LiveWork's hooks ------------------------------------------------------------------
    def attach(self, work):
        self.work = work
        work.pose_of = self.pose_of

    def pose_of(self, keyframe, iid):
        """The pose the live model takes for a keyframe (its node pose now): the refined one
        while the node pose is the one it was refined from, else the node pose moved by the
        correction of the nearest refined keyframe before it (after it, for the first ones)."""
        node = (keyframe.position, keyframe.orientation)
        r = self.refined.get(iid)
        if r is not None:
            if r[2] == node:
                return r[0], r[1]
            self._forget(iid)  # the node moved it (a loop closure): refined again
        return self.predict(iid, node)

    def predict(self, iid, node):
        if not self.refined_ids:
            return geometry.world_to_camera(*node)
        return predicted(self.refined_ids, lambda i: (self.refined[i][:2], self.refined[i][2]), iid, node)

    def _forget(self, iid):
        if self.refined.pop(iid, None) is not None:
            self.refined_ids.remove(iid)

    def _take(self, iid, qvec, tvec, node):
        if iid not in self.refined:
            bisect.insort(self.refined_ids, iid)
        self.refined[iid] = (tuple(qvec), tuple(tvec), node)

    # -- what the live model holds ---------------------------------------------------------

    def _node_poses(self):
        return node_poses(self.work)

    def _state(self):
        live = self.work.model
        order = sorted(live.images)
        observed = {i for i in order if live.by_image.get(i)}
        node = self._node_poses()
        unused = set()
        for a, b in live.matched_pairs - self.used_pairs:
            unused.add(a)
            unused.add(b)
        current = {i for i, then in self.covered.items() if then == node.get(i) and i not in unused}
        return order, observed, node, current

    def changed(self):
        order, observed, node, current = self._state()
        return [i for i in order if i not in current]

    def revisit_since(self):
        """Whether a revisit's pair (keyframes more than two windows apart in keyframe order)
        verified since the last refinement of the whole model."""
        order = sorted(self.work.model.images)
        position = {i: q for q, i in enumerate(order)}
        return any(abs(position.get(a, 0) - position.get(b, 0)) > 2 * self.size
                   for a, b in self.work.model.matched_pairs - self.used_pairs)

    # -- the worker loop's step ------------------------------------------------------------
    def allowance(self, kind):
        """CPU seconds the runs of a kind may still spend: their part of cpu_share (the windows
        local_fraction of it, the whole model the rest) of the session's time so far, less what
        they spent."""
        if self.started_at is None:
            self.started_at = self.clock()
        part = self.local_fraction if kind == "local" else 1.0 - self.local_fraction
        return part * self.cpu_share * (self.clock() - self.started_at) - self.cpu_by_kind[kind]

    def step(self, behind=False):
        """Polls the run under way (its result taken once it ended) and starts the next one
        when it is due and the budget allows; returns quickly. True while a run is under way.
        behind: the bridge's matching fell behind: the run under way is made nicer
        (YIELD_NICE) and none starts."""
        if self.work is None or self.work.model is None:
            return False
        if self.running is not None:
            run = self.running
            # refine_model stops itself at its --max-seconds; one that does not (a hung tool) is
            # killed at the options' timeout, as the finish's own run would be.
            if run.overdue():
                self.running = None
                self.failures += 1
                self.log("warn", "the %s refinement did not end within %.0f s and was killed" % (run.kind, run.timeout))
                return False
            if not run.poll():
                if behind:
                    run.yield_cpu()
                return True
            self._finish_run(run)
            self.running = None
        if behind:
            return False
        order, observed, node, current = self._state()
        pairs = len(self.work.model.matched_pairs)
        if len(observed) >= 2 and pairs >= max(self.every, (1.0 + self.global_growth) * self.global_pairs):
            # The whole model is due (it is what pulls the drift back along a loop): it starts
            # as soon as its part of the budget is not in debt, and the next waits until what
            # it spent beyond is paid back. (Gating it on its CPU estimated from the last run's
            # kept it from ever starting: a small model's run is mostly fixed costs.)
            if self.allowance("global") > 0:
                self.global_pairs = pairs
                self._start("global", order, [], node, self.global_seconds)
                return True
        if self.allowance("local") <= 0:
            return False
        new = [i for i in order if i in observed and i not in self.refined]
        if len(new) >= self.every:
            free, fixed = choose_window(order, observed, self.refined, lambda f: covisible_in(self.work.model, f),
                                        "local", size=self.size, max_fixed=self.max_fixed,
                                        partners=lambda f: partners_in(self.work.model, f))
            if free:
                self._start("local", free, fixed, node, self.local_seconds)
        return self.running is not None

    def _start(self, kind, free, fixed, node, max_seconds):
        work = self.work
        t0 = time.process_time()
        folder = tempfile.mkdtemp(prefix=".local_", dir=os.path.join(work.project.root, "sparse"))
        try:
            if kind == "global":
                model, pairs = work.model.to_model(), None
                used = set(work.model.matched_pairs)
            else:
                model, pairs = crop(work.model, free, fixed), window_pairs(work.model, free, fixed)
                used = set(pairs)
            colmap_model.write_model(model, os.path.join(folder, "input"), binary=True)
            # No --reference: a run is aligned to the poses it started from, its motion priors
            # theirs. (With the node's poses as the reference, live_odometry.test's online model
            # came out at 40.4 mm against the offline 12.3 mm; without, 12.4 mm.)
            reference = None
            options = self._options(max_seconds)
            matches = os.path.join(folder, "matches.bin")
            refiner.write_matches(work.project.database, matches, pairs,
                                  per_pair=self.global_matches if kind == "global" else 0)
            args = refiner.refine_model_command(refiner.find_refine_tool(self.finish_refinement.tool),
                                                os.path.join(folder, "input"), os.path.join(folder, "output"),
                                                os.path.join(folder, "report.json"), options,
                                                [model.images[i].name for i in fixed], reference=reference,
                                                matches=matches)
            proc = refiner.start_refine_model(args, getattr(work.project, "log_path", None))
        except (OSError, refiner.RefinementError, colmap_model.ModelError, KeyError, ValueError) as e:
            shutil.rmtree(folder, ignore_errors=True)
            self.failures += 1
            self.log("warn", "the %s refinement could not start: %s" % (kind, e))
            self.cpu_seconds += time.process_time() - t0
            self.cpu_by_kind[kind] += time.process_time() - t0
            return
        self.running = _Run(kind, free, fixed, folder, proc, {i: node.get(i) for i in free},
                            used, time.process_time() - t0, max_seconds, options.timeout)

    def _options(self, max_seconds):
        base = self.finish_refinement.options
        options = refiner.RefinementOptions(**{k: v for k, v in vars(base).items()})
        options.threads, options.max_seconds = 1, float(max_seconds)
        options.timeout = max(30.0, 4.0 * max_seconds + 30.0)
        return options

    def _finish_run(self, run):
        """The run's refined poses into the live model (and the predictions after them)."""
        t0 = time.process_time()
        try:
            cpu = run.rusage.ru_utime + run.rusage.ru_stime if run.rusage is not None else 0.0
            if run.status != 0:
                raise refiner.RefinementError("refine_model exited with %s" % run.status)
            report = refiner.read_report(os.path.join(run.folder, "report.json"))
            images = colmap_model._read_images_bin(os.path.join(run.folder, "output", "images.bin"))
            if report.get("refined"):
                self._take_poses(report, images, run.node, cover=run.kind == "global")
                # The points follow now, counted in the run's CPU (after a run of the whole model
                # this is every track: the 1-minute walk's finish spent 7.3 s triangulating
                # where it had spent 1.9 s without the runs, load 13).
                self.work.model.update()
                if run.kind == "global":
                    self.used_pairs |= run.pairs
            self.runs[run.kind] += 1
            self.history.append({"kind": run.kind, "free": len(run.free), "fixed": len(run.fixed),
                                 "status": report.get("status"), "iterations": report.get("iterations"),
                                 "cpu_seconds": round(cpu, 3), "seconds": round(time.monotonic() - run.started, 3)})
            del self.history[:-200]
        except (OSError, refiner.RefinementError, colmap_model.ModelError, KeyError, ValueError) as e:
            self.failures += 1
            self.log("warn", "the %s refinement gave nothing: %s" % (run.kind, e))
        finally:
            shutil.rmtree(run.folder, ignore_errors=True)
            spent = cpu + run.cpu + (time.process_time() - t0)
            self.cpu_seconds += spent
            self.cpu_by_kind[run.kind] += spent

    def _take_poses(self, report, images, node_then, cover):
        """Refined images whose node pose did not move meanwhile take their refined pose; the
        images never refined take the new corrections; the live model gets both."""
        live, fed = self.work.model, self.work.fed_poses
        moved = {}
        for entry in report["images"]:
            iid = entry["image_id"]
            if not entry.get("movable") or iid not in node_then or iid not in live.images:
                continue
            node_now = fed.get(live.images[iid].name)
            if node_now is None or node_now != node_then[iid]:
                continue  # the node moved it meanwhile: it stays to be refined
            im = images[iid]
            self._take(iid, im.qvec, im.tvec, node_now)
            if cover:
                self.covered[iid] = node_now
            moved[iid] = (im.qvec, im.tvec)
        for iid, im in live.images.items():
            if iid in moved:
                live.set_pose(iid, *moved[iid])
            elif iid not in self.refined and im.name in fed:
                live.set_pose(iid, *self.predict(iid, fed[im.name]))

    def wait(self, seconds):
        """Waits at most `seconds` for the run under way and takes its result; kills it when it
        would take longer."""
        run = self.running
        if run is None:
            return
        if run.wait(seconds):
            self._finish_run(run)
        else:
            self.log("info", "the %s refinement under way was stopped for the finish" % run.kind)
        self.running = None

    def summary(self):
        return {"runs": dict(self.runs), "failures": self.failures, "cpu_seconds": round(self.cpu_seconds, 3),
                "cpu_seconds_by_kind": {k: round(v, 3) for k, v in self.cpu_by_kind.items()},
                "keyframes_refined": len(self.refined), "cpu_share": self.cpu_share, "window": self.size,
                "every": self.every, "last_runs": self.history[-5:]}

    # -- the finish ------------------------------------------------------------------------
    def apply(self, project, model_path, model=None, matched=0):
        """ModelRefinement.apply's seam for the finish: `model_path` holds the live model at
        its poses now (refined where the runs refined it; `model` and `matched` are not needed:
        what changed since the runs is a window, not the whole model). The keyframes changed since they
        were last refined are refined (free), what they see held, then DIR/sparse/0 is the
        refined model and DIR/sparse/unrefined the model at the node's poses. Whatever fails,
        sparse/0 keeps the live model."""
        mr = self.finish_refinement
        start = time.monotonic()
        unrefined = os.path.join(os.path.dirname(model_path), "unrefined")
        budget = mr.options.max_seconds if mr.options.max_seconds > 0 else 60.0
        if self.running is not None:  # a run that ends within half the budget is worth waiting for
            wait = budget / 2
            if project.deadline is not None:  # at shutdown: a quarter of what is left at most
                wait = min(wait, max(0.0, (project.deadline - time.monotonic()) / 4))
            self.wait(wait)
        live = self.work.model
        try:
            order, observed, node, current = self._state()
            changed = [i for i in order if i not in current]
            node_poses = {i: geometry.world_to_camera(*p) for i, p in node.items()}
            at_node = all(np.allclose(geometry.rotation_of(node_poses[i][0]), im.r, atol=1e-9) and
                          np.allclose(node_poses[i][1], im.t, atol=1e-9)
                          for i, im in live.images.items() if i in node_poses)
            self.write_unrefined(model_path, node_poses, unrefined, at_node)
            if not changed:
                section = {"refined": True, "status": "unchanged", "message": "every keyframe was refined already",
                           "keyframes": [], "keyframes_kept": [], "seconds": time.monotonic() - start}
            else:
                free, fixed = choose_window(order, observed, current, lambda f: covisible_in(live, f), "changed",
                                            changed=changed, size=self.size, max_fixed=self.max_fixed,
                                            partners=lambda f: partners_in(live, f))
                if 2 * len(free) > len(order) or self.revisit_since():
                    # Most of it changed (no run of the whole model covered it yet): the held
                    # rest would be the worse refined part, and the crop saves little. Or a
                    # revisit's pair came since: with the keyframes between its two ends held,
                    # the loop's correction stays at its end (the 20 s walk closing its loop:
                    # 14.2 mm cropped, 8.3 mm whole).
                    free, fixed = list(order), []
                if not fixed:  # everything changed: the whole model, as ModelRefinement refines it
                    section = refiner.refine(model_path, model_path, mr.options, database=project.database,
                                             tool=mr.tool, log_path=project.log_path, deadline=project.deadline,
                                             log=lambda text: mr.log("info", text),
                                             progress=getattr(mr, "progress", None))
                    made = colmap_model.read_model(model_path)
                    report = {"images": [{"image_id": iid, "movable": True} for iid in made.images]}
                    if section["refined"]:
                        self._take_poses(report, made.images, {i: node.get(i) for i in free}, cover=True)
                        self.used_pairs |= live.matched_pairs
                        # The points follow now, within the finish: a change of the live model
                        # after it would show the live model again in place of the finished one
                        # (~points, live/model_topics.py).
                        live.update(final=True)
                else:
                    section = self._refine_crop(project, model_path, free, fixed, node)
                section.update(finish_free=len(free), finish_fixed=len(fixed))
                self.global_pairs = len(live.matched_pairs)  # the finish brought the whole model up to date
        except (refiner.RefinementError, ProjectError, DatabaseError, colmap_model.ModelError, OSError, KeyError,
                ValueError) as e:
            message = "refinement failed, the live model stays in %s: %s" % (model_path, e)
            mr.log("error", message)
            return {"refined": False, "status": "error", "error": message, "unrefined_path": unrefined,
                    "seconds": time.monotonic() - start, "options": mr.options.to_json(), "live": self.summary()}
        self._whole_model_corrections(section, node)
        section.update(unrefined_path=unrefined, seconds=time.monotonic() - start, live=self.summary())
        section.setdefault("options", mr.options.to_json())
        if section.get("keyframes_kept"):
            mr.log("warn", "refinement: %d keyframes kept their input pose (%s: %s)" % (
                len(section["keyframes_kept"]), section["keyframes_kept"][0]["name"],
                section["keyframes_kept"][0]["why"]))
        return section

    def _refine_crop(self, project, model_path, free, fixed, node):
        mr, live = self.finish_refinement, self.work.model
        folder = tempfile.mkdtemp(prefix=".finish_", dir=os.path.dirname(os.path.abspath(model_path)))
        try:
            model = crop(live, free, fixed)
            colmap_model.write_model(model, os.path.join(folder, "input"), binary=True)
            pairs = window_pairs(live, free, fixed)
            section = refiner.refine(os.path.join(folder, "input"), os.path.join(folder, "output"), mr.options,
                                     fixed=[model.images[i].name for i in fixed], database=project.database,
                                     tool=mr.tool, log_path=project.log_path, deadline=project.deadline,
                                     log=lambda text: mr.log("info", text), pairs=pairs,
                                     progress=getattr(mr, "progress", None))
            if section["refined"]:
                images = colmap_model._read_images_bin(os.path.join(folder, "output", "images.bin"))
                report = {"images": [{"image_id": i, "movable": True} for i in free]}
                self._take_poses(report, images, {i: node.get(i) for i in free}, cover=True)
                self.used_pairs |= set(pairs)
                live.update(final=True)  # the points follow the refined poses
                with project.db() as d:
                    ids = d.image_ids()
                project.write_model(live.to_model([ids[n] for n in self._names() if n in ids]), model_path)
            return section
        finally:
            shutil.rmtree(folder, ignore_errors=True)

    def _names(self):
        return [im.name for im in self.work.model.images.values()]

    @staticmethod
    def write_unrefined(model_path, node_poses, unrefined, at_node):
        """DIR/sparse/unrefined: the model at the node's poses (a copy when it is at them),
        written beside and swapped in."""
        if at_node:
            refiner.keep_copy(model_path, unrefined)
            return
        made = tempfile.mkdtemp(prefix=".unrefined_", dir=os.path.dirname(os.path.abspath(unrefined)))
        try:
            model = colmap_model.read_model(model_path)
            colmap_model.write_model(at_node_poses(model, node_poses), os.path.join(made, "m"), binary=True)
            durable.replace_folder(os.path.join(made, "m"), unrefined)
        finally:
            shutil.rmtree(made, ignore_errors=True)

    def _whole_model_corrections(self, section, node):
        """The corrections over every keyframe, against the node's poses (what the node would be
        sent, ~refined_path): the summary, and `keyframes` (one entry a keyframe: the finish's
        own where it refined the keyframe, with its observations)."""
        t, r = [], []
        finish = {k["name"]: k for k in section.get("keyframes", [])}
        keyframes = []
        for iid, im in sorted(self.work.model.images.items()):
            if iid not in node:
                continue
            centre, orientation = node[iid]
            t.append(float(np.linalg.norm(im.centre - np.asarray(centre, float))))
            c = (np.trace(geometry.rotation_of(orientation) @ im.r) - 1.0) / 2.0  # R_cw(node) vs R_wc(live)^T
            r.append(float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))))
            entry = dict(finish.get(im.name) or {"name": im.name, "refined": iid in self.refined, "kept": None,
                                                  "weak": False, "observations": None})
            entry.update(translation=t[-1], rotation_deg=r[-1])
            keyframes.append(entry)
        section["keyframes"] = keyframes
        t.sort()
        r.sort()
        section.update(translation_median=t[len(t) // 2] if t else 0.0, translation_max=t[-1] if t else 0.0,
                       rotation_median_deg=r[len(r) // 2] if r else 0.0, rotation_max_deg=r[-1] if r else 0.0,
                       keyframes_refined=sum(1 for a, b in zip(t, r) if a > 1e-9 or b > 1e-6))
