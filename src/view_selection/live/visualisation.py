"""What colmap_bridge shows of its model, without ROS (issue 36): the points as a PointCloud2
payload (x, y, z, rgb) and the keyframes as camera frusta, from the live model while the recording
goes on and from the finished model (DIR/sparse/0, refined) after a finish.

The model's poses are COLMAP's (world to camera) with the node's world as COLMAP's world
(live/work.py feeds the node's camera-to-world poses through geometry.world_to_camera), so the
points are already in the node's world frame and a camera's pose in that frame is
geometry.camera_to_world of its (qvec, tvec).

Cost. The cloud is a persistent buffer (16 bytes a point, slot per point): an update writes only
the points the live model made, moved or removed since the last one (LiveModel.take_changed), and a
point's colour is read once, when it gets its slot, from the per-image keypoint colours (each
keyframe image decoded once). Only the copy of the buffer into a message grows with the model
(a memcpy: dev/benchmark_model_topics measures both).
"""
import os

import numpy as np

from .. import geometry

POINT_STEP = 16  # x, y, z float32, rgb: 0x00RRGGBB in the 4 bytes of a float32, as RViz reads it
FIELDS = (("x", 0), ("y", 4), ("z", 8), ("rgb", 12))  # all FLOAT32, count 1
GREY = 0x808080


def pack_rgb(r, g, b):
    """0x00RRGGBB as uint32 (arrays or scalars)."""
    return (np.asarray(r, np.uint32) << 16) | (np.asarray(g, np.uint32) << 8) | np.asarray(b, np.uint32)


class KeypointColours:
    """Each keyframe image's colour at its keypoints, packed 0x00RRGGBB: an image is decoded once,
    when the first point seen in it needs a colour (a VGA image: about 5 ms; 8 KB kept for 2,048
    keypoints). Keypoints are in COLMAP's pixel convention (the centre of the top-left pixel at
    0.5, 0.5), so the pixel under a keypoint is its coordinates rounded down."""

    def __init__(self, image_dir):
        self.image_dir = image_dir
        self.cache = {}  # name -> (the keypoints array they were read for, colours)
        self.decoded = 0

    def of(self, name, keypoints):
        entry = self.cache.get(name)
        if entry is not None and (entry[0] is keypoints or (
                len(entry[0]) == len(keypoints) and np.array_equal(entry[0], keypoints))):
            return entry[1]
        colours = self.read(name, keypoints)
        if entry is None or entry[0] is not keypoints:
            self.cache[name] = (keypoints, colours)
        return colours

    def read(self, name, keypoints):
        keypoints = np.asarray(keypoints, np.float64).reshape(-1, 2)
        colours = np.full(len(keypoints), GREY, np.uint32)
        if not len(keypoints):
            return colours
        import cv2
        image = cv2.imread(os.path.join(self.image_dir, name), cv2.IMREAD_COLOR)
        self.decoded += 1
        if image is None:
            return colours  # unreadable: grey, and the model is still shown
        h, w = image.shape[:2]
        finite = np.all(np.isfinite(keypoints), axis=1)
        xy = np.where(finite[:, None], keypoints, 0.0)
        x = np.clip(np.floor(xy[:, 0]).astype(np.int64), 0, w - 1)
        y = np.clip(np.floor(xy[:, 1]).astype(np.int64), 0, h - 1)
        bgr = image[y, x]
        colours[finite] = pack_rgb(bgr[finite, 2], bgr[finite, 1], bgr[finite, 0])
        return colours


class CloudBuffer:
    """Points by key in a persistent float32 buffer (x, y, z, rgb per row), compact: a removed
    point's slot takes the last one, so the payload is the first `size` rows."""

    def __init__(self, capacity=1024):
        self.data = np.zeros((max(1, capacity), 4), np.float32)
        self.slot = {}   # key -> row
        self.keys = []   # row -> key
        self.size = 0

    def __len__(self):
        return self.size

    def _grow(self, need):
        if need > len(self.data):
            data = np.zeros((max(need, 2 * len(self.data)), 4), np.float32)
            data[:self.size] = self.data[:self.size]
            self.data = data

    def clear(self):
        self.slot, self.keys, self.size = {}, [], 0

    def put(self, keys, xyz, rgb=None):
        """Points by key: moved when known (their colour kept), added with `rgb` (uint32, or a
        function of the new rows' indices into keys giving them) when new."""
        rows = np.empty(len(keys), np.int64)
        new = []
        for q, key in enumerate(keys):
            row = self.slot.get(key)
            if row is None:
                new.append(q)
                row = self.size + len(new) - 1
            rows[q] = row
        if new:
            self._grow(self.size + len(new))
            for q in new:
                self.slot[keys[q]] = int(rows[q])
                self.keys.append(keys[q])
            self.size += len(new)
            colours = rgb(new) if callable(rgb) else (np.asarray(rgb, np.uint32)[new] if rgb is not None else GREY)
            self.data.view(np.uint32)[rows[new], 3] = colours
        if len(keys):
            self.data[rows, :3] = np.asarray(xyz, np.float64).reshape(-1, 3)
        return len(new)

    def remove(self, keys):
        removed = 0
        for key in keys:
            row = self.slot.pop(key, None)
            if row is None:
                continue
            last = self.size - 1
            if row != last:
                moved = self.keys[last]
                self.data[row] = self.data[last]
                self.keys[row] = moved
                self.slot[moved] = row
            self.keys.pop()
            self.size -= 1
            removed += 1
        return removed

    def xyz(self):
        return self.data[:self.size, :3]

    def rgb(self):
        return self.data.view(np.uint32)[:self.size, 3]

    def payload(self):
        """The PointCloud2 data: size x 16 bytes, little-endian (one copy of the buffer)."""
        return self.data[:self.size].astype("<f4", copy=False).tobytes()


class Frustum:
    """A keyframe's camera: its image id and name, its camera-to-world pose in the world frame
    (centre, quaternion w x y z) and the frustum's lines in the camera frame (pairs of points)."""
    __slots__ = ("id", "name", "centre", "orientation", "lines")

    def __init__(self, iid, name, centre, orientation, lines):
        self.id, self.name = int(iid), name
        self.centre, self.orientation, self.lines = tuple(centre), tuple(orientation), lines

    def __eq__(self, other):
        return (self.id, self.name, self.centre, self.orientation) == (other.id, other.name, other.centre,
                                                                       other.orientation)


def frustum_lines(fx, fy, cx, cy, width, height, depth):
    """The 8 segments (16 points, camera frame) of a pinhole frustum `depth` deep: the apex to the
    image's four corners and the rectangle (COLMAP's principal point: corners at 0 and width)."""
    corners = [((u - cx) / fx * depth, (v - cy) / fy * depth, depth)
               for u, v in ((0.0, 0.0), (width, 0.0), (width, height), (0.0, height))]
    lines = []
    for c in range(4):
        lines += [(0.0, 0.0, 0.0), corners[c], corners[c], corners[(c + 1) % 4]]
    return lines


def frustum_of(iid, name, qvec, tvec, camera, depth):
    """camera: (model name, width, height, params): PINHOLE-like params fx, fy, cx, cy, or SIMPLE
    ones f, cx, cy."""
    _, width, height, params = camera
    params = list(params)
    fx, fy, cx, cy = (params[0], params[0], params[1], params[2]) if len(params) == 3 else params[:4]
    centre, orientation = geometry.camera_to_world(qvec, tvec)
    return Frustum(iid, name, centre, orientation, frustum_lines(fx, fy, cx, cy, width, height, depth))


class ModelView:
    """The model as it is shown: the cloud (CloudBuffer payload) and the frusta.

    While the recording goes on it follows the live model (`live()`, after each update); after
    a finish it shows the finished model (`finished()`: sparse/0, refined); once the live model
    changes again (the recording went on) it follows the live model again, whose buffer was kept
    current meanwhile."""

    def __init__(self, image_dir, frustum_depth=0.1):
        self.colours = KeypointColours(image_dir)
        self.frustum_depth = float(frustum_depth)
        self.live_cloud = CloudBuffer()
        self.finished_cloud = None   # a CloudBuffer of the finished model, while it is shown
        self.live_poses = {}         # image id -> its rotation array when last shown (live model)
        self.live_by_id = {}         # image id -> its Frustum (live model)
        self.live_frusta = []
        self.finished_frusta = None
        self.cloud_version = 0       # bumped on every change of what is shown
        self.cameras_version = 0

    @property
    def showing_finished(self):
        return self.finished_cloud is not None

    def cloud(self):
        return self.finished_cloud if self.finished_cloud is not None else self.live_cloud

    def frusta(self):
        return self.finished_frusta if self.finished_frusta is not None else self.live_frusta

    # -- the live model ------------------------------------------------------------------------
    def live(self, model):
        """Takes what changed in a live/model.py LiveModel since the last call; returns how many
        points changed. The first call watches the model and takes every point it has."""
        if model.changed is None:
            model.watch_points()
        changed = model.take_changed()
        cameras = self._live_cameras(model)
        if not changed and not cameras:
            return 0
        points = model.points
        gone = [root for root in changed if root not in points]
        keep = [root for root in changed if root in points]
        self.live_cloud.remove(gone)
        if keep:
            xyz = np.array([points[root][0] for root in keep], np.float64)
            self.live_cloud.put(keep, xyz, lambda new: self._live_colours(model, [keep[q] for q in new]))
        if cameras or self.finished_frusta is not None:
            self.cameras_version += 1
        self.finished_cloud = self.finished_frusta = None  # the recording went on: the live model again
        self.cloud_version += 1
        return len(changed)

    def _live_colours(self, model, roots):
        """A new point's colour: its keypoint in the newest image that sees it (images are
        decoded in the order keyframes come, so that one is most often decoded already)."""
        out = np.empty(len(roots), np.uint32)
        for q, root in enumerate(roots):
            obs = model.points[root][2]
            iid = max(obs)
            im = model.images[iid]
            out[q] = self.colours.of(im.name, im.keypoints)[obs[iid]]
        return out

    def _live_cameras(self, model):
        """The live model's frusta: made for an image that came or whose pose moved, the others
        kept (all of them made again for each new keyframe cost 0.4 s of CPU a minute at 1,900
        keyframes, and grew with the session); True when any changed. A pose that moved has a new
        rotation array (_Image.set_pose makes it), so the check is one identity test an image."""
        images = model.images
        changed = False
        for iid, im in images.items():
            if self.live_poses.get(iid) is not im.r:
                self.live_poses[iid] = im.r
                self.live_by_id[iid] = frustum_of(iid, im.name, geometry.quaternion_of(im.r), im.t,
                                                  model.cameras[im.camera_id], self.frustum_depth)
                changed = True
        if len(self.live_by_id) != len(images):
            for iid in [i for i in self.live_by_id if i not in images]:
                del self.live_by_id[iid], self.live_poses[iid]
            changed = True
        if changed:
            self.live_frusta = [self.live_by_id[iid] for iid in sorted(self.live_by_id)]
        return changed

    # -- the finished model --------------------------------------------------------------------
    def finished(self, model, version=None):
        """A colmap/model.py Model (the finish's sparse/0) becomes what is shown: every point
        with its colour from its first observation's keypoint, every image a frustum. version:
        the view's cloud_version when the finish took the live model; when the view changed
        since (the recording went on), the finished model is older than the live one and is not
        shown. Returns whether it is."""
        if version is not None and version != self.cloud_version:
            return False
        ids = sorted(model.points)
        cloud = CloudBuffer(len(ids))
        by_id = model.images
        rgb = np.full(len(ids), GREY, np.uint32)
        colours = {}
        for q, pid in enumerate(ids):
            p = model.points[pid]
            if not len(p.image_ids):
                continue
            im = by_id.get(int(p.image_ids[0]))
            if im is None or not 0 <= int(p.point2D_idxs[0]) < len(im.xys):
                continue
            if im.id not in colours:
                colours[im.id] = self.colours.of(im.name, im.xys)
            rgb[q] = colours[im.id][int(p.point2D_idxs[0])]
        cloud.put(ids, np.array([model.points[i].xyz for i in ids], np.float64).reshape(-1, 3), rgb)
        self.finished_cloud = cloud
        self.finished_frusta = [
            frustum_of(im.id, im.name, im.qvec, im.tvec, (c.model, c.width, c.height, c.params), self.frustum_depth)
            for im in sorted(model.images.values(), key=lambda im: im.id)
            for c in (model.cameras[im.camera_id],)]
        self.cloud_version += 1
        self.cameras_version += 1
        return True
