"""COLMAP 3.8's sparse model (cameras, images, points3D), read and written in its binary (.bin)
and text (.txt) formats. One reader and one writer for the whole package: the known-pose model's
input, the bridge's and the tools' reading of what COLMAP made, and the statistics of a model.

Poses are COLMAP's: an image's (qvec, tvec) maps world to camera. Point ids, image ids and camera
ids are COLMAP's (the database's for images and cameras).
"""
import os
import struct
from collections.abc import Mapping

import numpy as np

from . import durable

# COLMAP's camera models by id: (name, number of parameters)
CAMERA_MODELS = {0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5),
                 4: ("OPENCV", 8), 5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5),
                 8: ("SIMPLE_RADIAL_FISHEYE", 4), 9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12)}
MODEL_IDS = {name: mid for mid, (name, _) in CAMERA_MODELS.items()}
INVALID_POINT3D = 2 ** 64 - 1  # COLMAP's kInvalidPoint3DId in images.bin (-1 in images.txt)


class ModelError(Exception):
    """A model folder that cannot be read."""


class Camera:
    __slots__ = ("id", "model", "width", "height", "params")

    def __init__(self, id, model, width, height, params):
        self.id, self.model, self.width, self.height = int(id), str(model), int(width), int(height)
        self.params = tuple(float(v) for v in params)


class Image:
    """An image of the model: its pose, camera, name and 2D points (x, y, point3D id or -1)."""
    __slots__ = ("id", "qvec", "tvec", "camera_id", "name", "xys", "point3D_ids")

    def __init__(self, id, qvec, tvec, camera_id, name, xys=None, point3D_ids=None):
        self.id, self.camera_id, self.name = int(id), int(camera_id), str(name)
        self.qvec = tuple(float(v) for v in qvec)
        self.tvec = tuple(float(v) for v in tvec)
        self.xys = np.zeros((0, 2)) if xys is None else np.asarray(xys, float).reshape(-1, 2)
        self.point3D_ids = (np.full(len(self.xys), -1, np.int64) if point3D_ids is None
                            else np.asarray(point3D_ids, np.int64).reshape(-1))


class Point3D:
    __slots__ = ("id", "xyz", "rgb", "error", "image_ids", "point2D_idxs")

    def __init__(self, id, xyz, rgb, error, image_ids, point2D_idxs):
        self.id = int(id)
        self.xyz = np.asarray(xyz, float).reshape(3)
        self.rgb = tuple(int(v) for v in rgb)
        self.error = float(error)
        self.image_ids = np.asarray(image_ids, np.int64).reshape(-1)
        self.point2D_idxs = np.asarray(point2D_idxs, np.int64).reshape(-1)

    @classmethod
    def of_arrays(cls, id, xyz, rgb, error, image_ids, point2D_idxs):
        """A point from values already in their types (int, float64 array of 3, tuple of 3 ints,
        float, int64 arrays), not converted again: a 30-minute session's 210,000 points."""
        p = cls.__new__(cls)
        p.id, p.xyz, p.rgb, p.error, p.image_ids, p.point2D_idxs = id, xyz, rgb, error, image_ids, point2D_idxs
        return p


class PointTable(Mapping):
    """{id: Point3D} held as arrays, the Point3D made when asked for: how the live model hands a
    whole session's points to the writer (a 30-minute session's 205,000 points were as many
    objects, made and walked again by the writer). Read-only. ids: N point ids; xyz: N x 3;
    rgb: N x 3 or one colour for all; error: N; offsets: N + 1, point q's observations are
    image_ids[offsets[q]:offsets[q + 1]] and point2D_idxs likewise."""

    def __init__(self, ids, xyz, rgb, error, offsets, image_ids, point2D_idxs):
        self.ids = np.asarray(ids, np.int64).reshape(-1)
        n = len(self.ids)
        self.xyz = np.asarray(xyz, float).reshape(n, 3)
        self.rgb = np.broadcast_to(np.asarray(rgb, np.uint8), (n, 3))
        self.error = np.asarray(error, float).reshape(n)
        self.offsets = np.asarray(offsets, np.int64).reshape(n + 1)
        self.image_ids = np.asarray(image_ids, np.int64).reshape(-1)
        self.point2D_idxs = np.asarray(point2D_idxs, np.int64).reshape(-1)
        if len(self.image_ids) != self.offsets[-1] or len(self.point2D_idxs) != self.offsets[-1]:
            raise ModelError("a point table whose tracks do not hold the observations its offsets say")
        self._rows = None

    def _point(self, q):
        a, b = self.offsets[q], self.offsets[q + 1]
        return Point3D.of_arrays(int(self.ids[q]), self.xyz[q], tuple(int(v) for v in self.rgb[q]),
                                 float(self.error[q]), self.image_ids[a:b], self.point2D_idxs[a:b])

    def __getitem__(self, pid):
        if self._rows is None:
            self._rows = dict(zip(self.ids.tolist(), range(len(self.ids))))
        return self._point(self._rows[pid])

    def __iter__(self):
        return iter(self.ids.tolist())

    def __len__(self):
        return len(self.ids)

    def values(self):
        return (self._point(q) for q in range(len(self.ids)))

    def items(self):
        return ((int(self.ids[q]), self._point(q)) for q in range(len(self.ids)))


class Model:
    """cameras {id: Camera}, images {id: Image}, points {id: Point3D} (a dict, or a PointTable)."""

    def __init__(self, cameras=None, images=None, points=None):
        self.cameras = cameras or {}
        self.images = images or {}
        self.points = points or {}

    def image_by_name(self):
        return {im.name: im for im in self.images.values()}

    def statistics(self):
        """What `colmap model_analyzer` reports: registered images, points, observations, mean
        track length, mean observations per image, mean reprojection error (the mean of the
        points' errors, as COLMAP's Reconstruction::ComputeMeanReprojectionError)."""
        if isinstance(self.points, PointTable):
            observations = int(self.points.offsets[-1])
            errors = self.points.error[self.points.error >= 0]
        else:
            observations = sum(len(p.image_ids) for p in self.points.values())
            errors = [p.error for p in self.points.values() if p.error >= 0]
        return {"registered": len(self.images), "points": len(self.points), "observations": observations,
                "track_length": observations / len(self.points) if self.points else 0.0,
                "obs_per_image": observations / len(self.images) if self.images else 0.0,
                "reprojection_error": float(np.mean(errors)) if len(errors) else 0.0}


# -- reading -------------------------------------------------------------------------------------
def read_model(folder):
    """The model in `folder`, binary (.bin) when present, else text (.txt)."""
    if all(os.path.isfile(os.path.join(folder, n + ".bin")) for n in ("cameras", "images", "points3D")):
        return Model(_read_cameras_bin(os.path.join(folder, "cameras.bin")),
                     _read_images_bin(os.path.join(folder, "images.bin")),
                     _read_points_bin(os.path.join(folder, "points3D.bin")))
    if all(os.path.isfile(os.path.join(folder, n + ".txt")) for n in ("cameras", "images", "points3D")):
        return Model(_read_cameras_txt(os.path.join(folder, "cameras.txt")),
                     _read_images_txt(os.path.join(folder, "images.txt")),
                     _read_points_txt(os.path.join(folder, "points3D.txt")))
    raise ModelError("%s holds no COLMAP model (cameras, images, points3D as .bin or .txt)" % folder)


class _Reader:
    def __init__(self, path):
        with open(path, "rb") as f:
            self.data = f.read()
        self.at, self.path = 0, path

    def take(self, fmt):
        size = struct.calcsize(fmt)
        if self.at + size > len(self.data):
            raise ModelError("%s ends early (at byte %d)" % (self.path, self.at))
        values = struct.unpack_from(fmt, self.data, self.at)
        self.at += size
        return values

    def array(self, dtype, count):
        size = np.dtype(dtype).itemsize * count
        if self.at + size > len(self.data):
            raise ModelError("%s ends early (at byte %d)" % (self.path, self.at))
        a = np.frombuffer(self.data, dtype, count, self.at)
        self.at += size
        return a

    def name(self):
        end = self.data.find(b"\0", self.at)
        if end < 0:
            raise ModelError("%s: an image name without its end" % self.path)
        text = self.data[self.at:end].decode("utf-8")
        self.at = end + 1
        return text


def _read_cameras_bin(path):
    r = _Reader(path)
    cameras = {}
    for _ in range(r.take("<Q")[0]):
        cid, mid, w, h = r.take("<iiQQ")
        if mid not in CAMERA_MODELS:
            raise ModelError("%s: camera %d has an unknown model id %d" % (path, cid, mid))
        name, n = CAMERA_MODELS[mid]
        cameras[cid] = Camera(cid, name, w, h, r.take("<%dd" % n))
    return cameras


def _read_images_bin(path):
    r = _Reader(path)
    images = {}
    for _ in range(r.take("<Q")[0]):
        iid, qw, qx, qy, qz, tx, ty, tz, cid = r.take("<idddddddi")
        name = r.name()
        n = r.take("<Q")[0]
        raw = r.array(np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<u8")]), n)
        ids = raw["id"].astype(np.int64)  # kInvalidPoint3DId wraps to -1
        images[iid] = Image(iid, (qw, qx, qy, qz), (tx, ty, tz), cid, name,
                            np.stack([raw["x"], raw["y"]], axis=1), ids)
    return images


def _read_points_bin(path):
    r = _Reader(path)
    points = {}
    for _ in range(r.take("<Q")[0]):
        pid, x, y, z, cr, cg, cb, err = r.take("<QdddBBBd")
        n = r.take("<Q")[0]
        track = r.array(np.dtype([("image", "<i4"), ("idx", "<i4")]), n)
        points[pid] = Point3D(pid, (x, y, z), (cr, cg, cb), err, track["image"], track["idx"])
    return points


def _lines(path):
    with open(path) as f:
        return [line.rstrip("\n") for line in f if not line.startswith("#")]


def _read_cameras_txt(path):
    cameras = {}
    for line in _lines(path):
        parts = line.split()
        if not parts:
            continue
        cid = int(parts[0])
        cameras[cid] = Camera(cid, parts[1], int(parts[2]), int(parts[3]), [float(v) for v in parts[4:]])
    return cameras


def _read_images_txt(path):
    images = {}
    lines = _lines(path)
    for at in range(0, len(lines) - 1, 2):
        parts = lines[at].split()
        if len(parts) < 10:
            continue
        points = lines[at + 1].split()
        xys = np.array([[float(points[i]), float(points[i + 1])] for i in range(0, len(points) - 2, 3)]).reshape(-1, 2)
        ids = np.array([int(points[i + 2]) for i in range(0, len(points) - 2, 3)], np.int64)
        iid = int(parts[0])
        images[iid] = Image(iid, [float(v) for v in parts[1:5]], [float(v) for v in parts[5:8]], int(parts[8]),
                            " ".join(parts[9:]), xys, ids)
    return images


def _read_points_txt(path):
    points = {}
    for line in _lines(path):
        parts = line.split()
        if len(parts) < 8:
            continue
        pid = int(parts[0])
        track = np.array([int(v) for v in parts[8:]], np.int64).reshape(-1, 2)
        points[pid] = Point3D(pid, [float(v) for v in parts[1:4]], [int(v) for v in parts[4:7]], float(parts[7]),
                              track[:, 0], track[:, 1])
    return points


# -- writing -------------------------------------------------------------------------------------
def write_model(model, folder, binary=True):
    """Writes cameras, images and points3D into `folder` (made when missing), each file written
    to a temporary name, fsynced and renamed, and the folder fsynced (durable.write_atomically),
    so a reader never sees half a file, also after a power loss."""
    os.makedirs(folder, exist_ok=True)
    ext = ".bin" if binary else ".txt"
    for name, writer in (("cameras", _cameras_bin if binary else _cameras_txt),
                         ("images", _images_bin if binary else _images_txt),
                         ("points3D", _points_bin if binary else _points_txt)):
        durable.write_atomically(os.path.join(folder, name + ext), writer(model))


def _cameras_bin(model):
    out = [struct.pack("<Q", len(model.cameras))]
    for c in sorted(model.cameras.values(), key=lambda c: c.id):
        out.append(struct.pack("<iiQQ", c.id, MODEL_IDS[c.model], c.width, c.height))
        out.append(struct.pack("<%dd" % len(c.params), *c.params))
    return b"".join(out)


def _images_bin(model):
    out = [struct.pack("<Q", len(model.images))]
    for im in sorted(model.images.values(), key=lambda i: i.id):
        out.append(struct.pack("<idddddddi", im.id, *im.qvec, *im.tvec, im.camera_id))
        out.append(im.name.encode("utf-8") + b"\0")
        out.append(struct.pack("<Q", len(im.xys)))
        rec = np.zeros(len(im.xys), np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<u8")]))
        rec["x"], rec["y"] = im.xys[:, 0], im.xys[:, 1]
        rec["id"] = im.point3D_ids.astype(np.int64).view(np.uint64)  # -1: kInvalidPoint3DId
        out.append(rec.tobytes())
    return b"".join(out)


def _point_arrays(model):
    """The model's points as a PointTable in id order (the table itself when it is one)."""
    table = model.points
    if isinstance(table, PointTable) and np.all(np.diff(table.ids) > 0):
        return table
    points = sorted(model.points.values(), key=lambda p: p.id)
    n = len(points)
    lengths = np.fromiter((len(p.image_ids) for p in points), np.int64, n)
    rgb = [p.rgb for p in points]
    return PointTable(np.fromiter((p.id for p in points), np.int64, n),
                      np.array([p.xyz for p in points], float).reshape(n, 3),
                      rgb[0] if n and rgb.count(rgb[0]) == n else np.array(rgb, np.int64).reshape(n, 3),
                      np.fromiter((p.error for p in points), float, n),
                      np.concatenate([[0], np.cumsum(lengths)]),
                      np.concatenate([p.image_ids for p in points]) if n else [],
                      np.concatenate([p.point2D_idxs for p in points]) if n else [])


def _points_bin(model):
    """points3D.bin: the points' records (51 bytes each) and their tracks (8 bytes an
    observation) made as two arrays, then each put at its place in the file's bytes at once (a
    30-minute session's 200,000 points: 0.53 s point by point, 0.13 s joined point by point,
    0.09 s so)."""
    table = _point_arrays(model)
    n = len(table)
    lengths = np.diff(table.offsets)
    head = np.zeros(n, np.dtype([("id", "<u8"), ("xyz", "<f8", 3), ("rgb", "u1", 3), ("error", "<f8"),
                                 ("length", "<u8")]))  # packed: 51 bytes
    if n:
        head["id"] = table.ids
        head["xyz"] = table.xyz
        head["rgb"] = table.rgb
        head["error"] = table.error
        head["length"] = lengths
    track = np.zeros(int(table.offsets[-1]), np.dtype([("image", "<i4"), ("idx", "<i4")]))
    if len(track):
        track["image"] = table.image_ids
        track["idx"] = table.point2D_idxs
    # Point q's record goes after q records and offsets[q] observations; its track right after it.
    w = head.dtype.itemsize
    out = np.empty(8 + w * n + 8 * len(track), np.uint8)
    out[:8] = np.frombuffer(struct.pack("<Q", n), np.uint8)
    # Byte column by byte column: the index arrays stay one entry a point (or an observation),
    # not one a byte (51 a point: 80 MB for a 30-minute session's 200,000 points).
    if n:
        at = 8 + w * np.arange(n, dtype=np.int64) + 8 * table.offsets[:-1]
        head_bytes = head.view(np.uint8).reshape(n, w)
        for j in range(w):
            out[at + j] = head_bytes[:, j]
    if len(track):
        owner = np.repeat(np.arange(n, dtype=np.int64), lengths)
        at = 8 + w * (owner + 1) + 8 * np.arange(len(track), dtype=np.int64)
        track_bytes = track.view(np.uint8).reshape(len(track), 8)
        for j in range(8):
            out[at + j] = track_bytes[:, j]
    return out.tobytes()


def _cameras_txt(model):
    lines = ["# Camera list with one line of data per camera:",
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"]
    for c in sorted(model.cameras.values(), key=lambda c: c.id):
        lines.append("%d %s %d %d %s" % (c.id, c.model, c.width, c.height, " ".join("%.17g" % v for v in c.params)))
    return ("\n".join(lines) + "\n").encode()


def _images_txt(model):
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    for im in sorted(model.images.values(), key=lambda i: i.id):
        lines.append("%d %s %d %s" % (im.id, " ".join("%.17g" % v for v in im.qvec + im.tvec), im.camera_id, im.name))
        lines.append(" ".join("%.17g %.17g %d" % (x, y, pid) for (x, y), pid in zip(im.xys, im.point3D_ids)))
    return ("\n".join(lines) + "\n").encode()


def _points_txt(model):
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"]
    for p in sorted(model.points.values(), key=lambda p: p.id):
        track = " ".join("%d %d" % (i, j) for i, j in zip(p.image_ids, p.point2D_idxs))
        lines.append("%d %s %d %d %d %.17g %s" % (p.id, " ".join("%.17g" % v for v in p.xyz), *p.rgb, p.error, track))
    return ("\n".join(lines) + "\n").encode()
