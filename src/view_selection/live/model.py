"""The live model: tracks and 3D points at the node's poses, triangulated as pairs verify, so that
the finish only closes the tail instead of triangulating the whole session (issue 28).

Observations are (image id, keypoint index) of the project's database. Every verified match
joins the two observations' tracks (union-find), unless that would give a track two keypoints of
one image (the match is then left out, as COLMAP's track building does). A track touched by a
new match, or one of whose images moved (a loop closure corrected its pose), is triangulated
again at the next `update()`: a linear (DLT) point from all its observations, then Gauss-Newton
on the reprojection error. A track whose point was triangulated from at least three
observations and that only grew since (fewer than twice as many observations) is extended
instead: each new observation joins the point when it lies within `max_error_px` of its
projection, as COLMAP's incremental triangulator continues a track. Two tracks with points that a
match joins (a revisit) are one such track: the observations of the one with fewer join the
other's point, unless they would double it. So the cost of an update is
that of its new observations, not of whole tracks that grow with every revisit (issue 28: in a
room walked round for 3 minutes the mean track reached 22 observations and a full
re-triangulation 0.31 s of CPU an update). A full triangulation is the package's one
(triangulation.py, the C++ that refine_model re-triangulates with, issue 34): observations
further than `max_error_px` from the point or behind their camera are dropped (the worst first,
the point made again from the rest; after a few rounds every one beyond the limit at once), and a
point seen at less than `min_angle_deg` of triangulation angle is not kept. The angle is COLMAP
3.8's point_triangulator default (tri_min_angle 1.5 deg); the error is tighter than its 4 px
(filter_max_reproj_error): measured on the kitchen at its poses, 3 px keeps 5,934 points at 1.34
px mean error where 4 px keeps 6,431 at 1.73 px, and COLMAP's point_triangulator on the same
matches 4,680 at 1.62 px (docs/live.md).

Cameras, keypoints and poses are in COLMAP's convention (the database's keypoints, the cameras'
principal points shifted by half a pixel, world-to-camera poses), so the model written is the one
point_triangulator would start from, with its points.
"""
from itertools import compress

import numpy as np

from .. import geometry, triangulation
from ..colmap import model as colmap_model


class _Image:
    __slots__ = ("id", "name", "camera_id", "r", "t", "centre", "k", "intrinsics", "keypoints")

    def __init__(self, iid, name, camera_id, qvec, tvec, params, keypoints):
        self.id, self.name, self.camera_id = iid, name, camera_id
        self.set_pose(qvec, tvec)
        fx, fy, cx, cy = (float(v) for v in params[:4])
        self.k = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        self.intrinsics = (fx, fy, cx, cy)
        self.keypoints = np.asarray(keypoints, np.float64).reshape(len(keypoints), -1)[:, :2] if len(keypoints) \
            else np.zeros((0, 2))

    def set_pose(self, qvec, tvec):
        self.r = geometry.rotation_of(qvec)
        self.t = np.asarray(tvec, np.float64)
        self.centre = -self.r.T @ self.t

    def projection(self):
        return self.k @ np.hstack([self.r, self.t.reshape(3, 1)])


# The finish's update tries again every track that gave no point and has grown since, however
# little, up to this many observations; a longer one waits, as in a live update, until it grew by
# half. Those are chains of matches across a revisit's drift that a one-by-one triangulation
# takes apart at a cost quadratic in their length: on a 10-minute walk on odometry the 6,443
# grown tracks (median 32 observations, up to 344) took 1.37 s of CPU for 1,182 more points;
# the 2,201 of at most 20 took 0.08 s for 984 of them (30 minutes: 4.4 s in all).
FINAL_RETRY_MAX_OBSERVATIONS = 20


class LiveModel:
    def __init__(self, max_error_px=triangulation.MAX_ERROR_PX, min_angle_deg=triangulation.MIN_ANGLE_DEG):
        self.max_error_px, self.min_angle_deg = float(max_error_px), float(min_angle_deg)
        self.images = {}      # image id -> _Image
        self.cameras = {}     # camera id -> (model name, width, height, params)
        self.parent = {}      # observation -> parent (union-find)
        self.members = {}     # root -> {image id: keypoint index}
        self.dirty = set()    # roots to triangulate again (or to extend)
        self.full = set()     # roots that must be triangulated from scratch (a pose moved, two points merged)
        self.full_size = {}   # root -> observations of its point at its last full triangulation
        self.failed_size = {}  # root -> observations when it last gave no point (retried once it grew by half)
        self.pending = {}     # root -> {image id: keypoint} joined since its point was made
        self.observations_triangulated = 0  # observations handled by update(), for the benchmarks and tests
        self.points = {}      # root -> (xyz, error, {image id: keypoint index} of the inliers)
        self.by_image = {}    # image id -> set of roots with an observation in it
        self.conflicts = 0    # matches left out: they would give a track two keypoints of one image
        self.matched_pairs = set()
        self.changed = None   # with watch_points(): roots whose point was made, moved or removed since taken

    def watch_points(self):
        """From now on, record the roots whose point changes, for take_changed() (what the bridge
        publishes is updated with them: live/visualisation.py). Off by default: nothing takes them
        offline."""
        if self.changed is None:
            self.changed = set(self.points)

    def take_changed(self):
        """The roots whose point was made, moved or removed since the last call (a root no longer
        in `points` lost its point)."""
        changed, self.changed = self.changed, set()
        return changed or set()

    # -- images ------------------------------------------------------------------------------
    def add_image(self, iid, name, camera_id, camera, qvec, tvec, keypoints):
        """An image of the database with its pose (COLMAP's world-to-camera) and keypoints;
        again for an image already there: a new pose, and its tracks are triangulated again."""
        self.cameras[camera_id] = camera
        if iid in self.images and (len(self.images[iid].keypoints) or not len(keypoints)):
            self.set_pose(iid, qvec, tvec)
            return
        self.images[iid] = _Image(iid, name, camera_id, qvec, tvec, camera[3], keypoints)  # new, or features came
        self.by_image.setdefault(iid, set())

    def set_pose(self, iid, qvec, tvec):
        im = self.images[iid]
        old = (im.r.copy(), im.t.copy())
        im.set_pose(qvec, tvec)
        if not (np.allclose(old[0], im.r, atol=1e-12) and np.allclose(old[1], im.t, atol=1e-12)):
            roots = {self._find(o) for o in self._observations_of(iid)}
            self.dirty |= roots
            self.full |= roots

    def _observations_of(self, iid):
        return [(iid, kp) for root in self.by_image.get(iid, ()) for img, kp in self.members.get(root, {}).items()
                if img == iid]

    # -- tracks ------------------------------------------------------------------------------
    def _find(self, o):
        parent = self.parent
        up = parent.get(o)
        if up is None or up == o:
            return o  # a lone observation, or a root: most of what a match looks up
        root = o
        while parent.get(root, root) != root:
            root = parent[root]
        while parent.get(o, o) != root:  # path compression
            parent[o], o = root, parent[o]
        return root

    def add_matches(self, id1, id2, matches):
        """Verified matches of a pair (M x 2 keypoint indices of id1 and id2)."""
        self.matched_pairs.add((min(id1, id2), max(id1, id2)))
        find, members, by_image = self._find, self.members, self.by_image
        for k1, k2 in np.asarray(matches, np.int64).reshape(-1, 2).tolist():
            ra, rb = find((id1, k1)), find((id2, k2))
            if ra == rb:
                continue
            # A lone observation (no track yet) is its own root and has nothing to clear.
            ma, mb = members.get(ra), members.get(rb)
            lone_a, lone_b = ma is None, mb is None
            if lone_a:
                ma = {id1: k1}
            if lone_b:
                mb = {id2: k2}
            if len(ma) < len(mb):
                ra, rb, ma, mb, lone_a, lone_b = rb, ra, mb, ma, lone_b, lone_a
            # an image both tracks see with different keypoints (looked for in the smaller one)
            if any(ma.get(img, kp) != kp for img, kp in mb.items()):
                self.conflicts += 1
                continue
            self.parent[rb] = ra
            self.parent.setdefault(ra, ra)
            ma.update(mb)
            members[ra] = ma
            if not lone_b:
                del members[rb]
                if self.points.pop(rb, None) is not None or rb in self.full:
                    if self.changed is not None:
                        self.changed.add(rb)
                    if not self._extensible(ra, self.full):
                        self.full.add(ra)  # two points (or one to redo) become one: triangulated from scratch
                    # else rb's observations join ra's point as a growing track's do (pending, below):
                    # each where it projects within max_error_px, and the whole triangulated again once
                    # the point's observations would double (the cost of a merge is the smaller side's)
                self.full.discard(rb)
                self.full_size.pop(rb, None)
                self.failed_size.pop(rb, None)
                self.pending.pop(rb, None)
                self.dirty.discard(rb)
            self.pending.setdefault(ra, {}).update(mb)  # new to ra's point, if it has one
            self.dirty.add(ra)
            for img in (ma if lone_a else mb):  # (ma holds mb's now) ma's images know ra, unless it was lone
                roots = by_image.get(img)
                if roots is None:
                    by_image[img] = roots = set()
                if not lone_b:
                    roots.discard(rb)
                roots.add(ra)

    def _extensible(self, root, full):
        """A track whose point new observations may join without triangulating it again: its point
        made from at least three observations, and not to be made again (`full`: the roots whose
        pose moved or whose points merged)."""
        return root in self.points and root not in full and self.full_size.get(root, 0) >= 3

    # -- triangulation -----------------------------------------------------------------------
    def update(self, final=False):
        """Triangulates the tracks that changed; returns how many. final: also every track that
        gave no point and has grown since, however little, up to FINAL_RETRY_MAX_OBSERVATIONS
        (the finish: nothing short waits longer)."""
        if final:
            self.dirty |= {root for root, size in self.failed_size.items()
                           if root in self.members and size < len(self.members[root]) <= FINAL_RETRY_MAX_OBSERVATIONS}
        todo = [root for root in self.dirty if root in self.members]
        full, self.dirty, self.full = self.full, set(), set()
        tracks, extend = [], []
        for root in todo:
            point = self.points.get(root)
            joined = self.pending.pop(root, {})
            if self._extensible(root, full) and len(point[2]) + len(joined) < 2 * self.full_size[root]:
                # Only what joined is looked at: the cost is that of the new observations.
                new = {img: kp for img, kp in joined.items() if img in self.images and img not in point[2]}
                if new:
                    extend.append((root, new))
                continue
            size, failed = len(self.members[root]), self.failed_size.get(root, 0)
            if point is None and root not in full and (
                    size <= failed if final and size <= FINAL_RETRY_MAX_OBSERVATIONS else
                    size < max(failed + 2, 1.5 * failed)):
                continue  # it gave no point with nearly as many observations: not yet again
            obs = {img: kp for img, kp in self.members[root].items() if img in self.images}
            if len(obs) >= 2:
                tracks.append((root, obs))
            else:
                if self.points.pop(root, None) is not None and self.changed is not None:
                    self.changed.add(root)
                self.full_size.pop(root, None)
        if extend:
            self._extend(extend)
        if tracks:
            self._triangulate(tracks)
        return len(todo)

    def _extend(self, extend):
        """New observations of tracks with a point: each joins its point when it projects within
        max_error_px, in front of the camera; the point itself stays."""
        rows = [(root, img, kp) for root, new in extend for img, kp in new.items()]
        self.observations_triangulated += len(rows)
        x = np.array([self.points[root][0] for root, _, _ in rows])                          # N x 3
        r, t, k, xy = self._gather(np.fromiter((img for _, img, _ in rows), np.int64, len(rows)),
                                   np.fromiter((kp for _, _, kp in rows), np.int64, len(rows)))
        pc = np.einsum("nij,nj->ni", r, x) + t
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack([k[:, 0] * pc[:, 0] / z + k[:, 2], k[:, 1] * pc[:, 1] / z + k[:, 3]], 1)
            errors = np.linalg.norm(uv - xy, axis=1)
        ok = np.isfinite(errors) & (z > 0) & (errors <= self.max_error_px)
        for (root, img, kp), good, e in zip(rows, ok.tolist(), errors.tolist()):
            if good:
                xyz, mean, obs = self.points[root]
                obs[img] = kp  # the point's own dict (made by the triangulation): no copy per observation
                self.points[root] = (xyz, (mean * (len(obs) - 1) + float(e)) / len(obs), obs)

    def _triangulate(self, tracks):
        """Points of the tracks [(root, {image id: keypoint})] by the package's one triangulation
        (triangulation.py: the C++ of refine_model's re-triangulation), all in one call."""
        lengths = [len(obs) for _, obs in tracks]
        total = sum(lengths)
        self.observations_triangulated += total
        r, t, k, xy = self._gather(np.fromiter((img for _, obs in tracks for img in obs), np.int64, total),
                                   np.fromiter((kp for _, obs in tracks for kp in obs.values()), np.int64, total))
        points, ok, mean_error, inlier = triangulation.triangulate_tracks(
            lengths, r, t, k, xy, self.max_error_px, self.min_angle_deg, triangulation.DROP_ONE_BY_ONE)
        ok, mean_error, inlier = ok.tolist(), mean_error.tolist(), inlier.tolist()
        at = 0
        for q, (root, obs) in enumerate(tracks):
            kept = dict(compress(obs.items(), inlier[at:at + len(obs)]))
            at += len(obs)
            if ok[q]:
                self.points[root] = (points[q], mean_error[q], kept)
                self.full_size[root] = len(kept)
                self.failed_size.pop(root, None)
            else:
                self.points.pop(root, None)
                self.failed_size[root] = len(self.members.get(root, obs))
        if self.changed is not None:
            self.changed.update(root for root, _ in tracks)  # made, moved or removed

    def _gather(self, img, kp):
        """Per observation (image ids and keypoint indices, int arrays of N): the world-to-camera
        rotations N x 3 x 3 and translations N x 3, the intrinsics N x 4 (fx, fy, cx, cy) and the
        keypoints N x 2, gathered image by image (one lookup an image, not one an observation)."""
        ids, inverse = np.unique(img, return_inverse=True)
        ims = [self.images[i] for i in ids.tolist()]
        r = np.array([im.r for im in ims]).reshape(-1, 3, 3)[inverse]
        t = np.array([im.t for im in ims]).reshape(-1, 3)[inverse]
        k = np.array([im.intrinsics for im in ims], np.float64).reshape(-1, 4)[inverse]
        xy = np.empty((len(img), 2))
        order = np.argsort(inverse, kind="stable")
        bounds = np.searchsorted(inverse[order], np.arange(len(ims) + 1)).tolist()
        for j, im in enumerate(ims):
            at = order[bounds[j]:bounds[j + 1]]
            xy[at] = im.keypoints[kp[at]]
        return r, t, k, xy

    # -- the COLMAP model --------------------------------------------------------------------
    def to_model(self, image_ids=None, seen_by=None):
        """A colmap.model.Model of the images (all, or those ids) and the points seen by at
        least two of them; point ids are 1, 2, ... in track order. seen_by: only the points with
        an observation in one of these images (a window of the refinement, refinement/local.py).
        Built with arrays, not point by point (a 30-minute session's 210,000 points took 2.1 s),
        and its points are a colmap.model.PointTable: the writer takes the arrays as they are."""
        keep = set(self.images) if image_ids is None else set(image_ids) & set(self.images)
        if seen_by is None:
            roots = self.points
        else:
            seen_by = set(seen_by)
            roots = {r for i in seen_by for r in self.by_image.get(i, ())} & self.points.keys()
        roots = sorted(roots)
        points = [self.points[r] for r in roots]
        counts = np.fromiter((len(p[2]) for p in points), np.int64, len(points))
        total = int(counts.sum())
        img = np.fromiter((i for p in points for i in p[2]), np.int64, total)
        kp = np.fromiter((k for p in points for k in p[2].values()), np.int64, total)
        owner = np.repeat(np.arange(len(points)), counts)
        kept = np.isin(img, np.fromiter(keep, np.int64, len(keep)))
        valid = np.bincount(owner[kept], minlength=len(points)) >= 2
        if seen_by is not None:
            seen = kept & np.isin(img, np.fromiter(seen_by, np.int64, len(seen_by)))
            valid &= np.bincount(owner[seen], minlength=len(points)) > 0
        take = kept & valid[owner]
        point_id = np.cumsum(valid)  # 1, 2, ... over the valid points, by track order
        img, kp, pid = img[take], kp[take], point_id[owner[take]]
        order = np.lexsort((img, pid))  # by point, then image
        img, kp, pid = img[order], kp[order], pid[order]
        m = colmap_model.Model()
        made = np.flatnonzero(valid)
        m.points = colmap_model.PointTable(
            np.arange(1, len(made) + 1), np.array([points[q][0] for q in made], float).reshape(-1, 3),
            (128, 128, 128), np.fromiter((points[q][1] for q in made), float, len(made)),
            np.searchsorted(pid, np.arange(1, len(made) + 2)), img, kp)
        by_image = np.argsort(img, kind="stable")
        names, first = np.unique(img[by_image], return_index=True)
        groups = dict(zip(names.tolist(), np.split(by_image, first[1:]) if len(first) else []))
        for iid in sorted(keep):
            im = self.images[iid]
            name, w, h, params = self.cameras[im.camera_id]
            m.cameras[im.camera_id] = colmap_model.Camera(im.camera_id, name, w, h, params)
            ids = np.full(len(im.keypoints), -1, np.int64)
            rows = groups.get(iid)
            if rows is not None:
                ids[kp[rows]] = pid[rows]
            m.images[iid] = colmap_model.Image(iid, geometry.quaternion_of(im.r), tuple(im.t), im.camera_id, im.name,
                                               im.keypoints, ids)
        return m
