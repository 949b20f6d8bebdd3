"""COLMAP 3.8's database (database.db), read and written in COLMAP's own schema.

Everything the project reads from or writes into a COLMAP database goes through here: cameras,
images, keypoints, descriptors, raw matches and verified two-view geometries. A database made here
is the one `colmap database_creator` makes; COLMAP's commands (feature_extractor,
matches_importer, point_triangulator, mapper, exhaustive_matcher, the GUI) read and extend it.

Layouts (COLMAP 3.8, src/base/database.cc):
  keypoints       float32 rows x 2, 4 or 6 (x, y[, scale, orientation | , a11, a12, a21, a22]),
                  pixel centres at +0.5 (the top-left pixel's centre is (0.5, 0.5))
  descriptors     uint8 rows x 128
  matches         uint32 rows x 2, point indices of image_id1 and image_id2 of the pair id
  two_view_geometries: the inlier matches as above, config (TwoViewGeometry::ConfigurationType),
                  F, E, H (3x3 float64, row-major), qvec (w, x, y, z), tvec: the pose of the second
                  image relative to the first
"""
import contextlib
import sqlite3

import numpy as np

MAX_IMAGE_ID = 2147483647  # COLMAP's kMaxNumImages
PINHOLE = 1                # COLMAP's camera model id of PINHOLE (fx, fy, cx, cy)
# TwoViewGeometry::ConfigurationType
UNDEFINED, DEGENERATE, CALIBRATED, UNCALIBRATED, PLANAR = 0, 1, 2, 3, 4

SCHEMA = """
CREATE TABLE IF NOT EXISTS cameras (
    camera_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, model INTEGER NOT NULL,
    width INTEGER NOT NULL, height INTEGER NOT NULL, params BLOB, prior_focal_length INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS images (
    image_id INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, name TEXT NOT NULL UNIQUE,
    camera_id INTEGER NOT NULL, prior_qw REAL, prior_qx REAL, prior_qy REAL, prior_qz REAL,
    prior_tx REAL, prior_ty REAL, prior_tz REAL,
    CONSTRAINT image_id_check CHECK(image_id >= 0 and image_id < 2147483647),
    FOREIGN KEY(camera_id) REFERENCES cameras(camera_id));
CREATE UNIQUE INDEX IF NOT EXISTS index_name ON images(name);
CREATE TABLE IF NOT EXISTS keypoints (
    image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB,
    FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE);
CREATE TABLE IF NOT EXISTS descriptors (
    image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB,
    FOREIGN KEY(image_id) REFERENCES images(image_id) ON DELETE CASCADE);
CREATE TABLE IF NOT EXISTS matches (
    pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB);
CREATE TABLE IF NOT EXISTS two_view_geometries (
    pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB,
    config INTEGER NOT NULL, F BLOB, E BLOB, H BLOB, qvec BLOB, tvec BLOB);
"""


class DatabaseError(Exception):
    """A file that is not a COLMAP database, or a write COLMAP would not read."""


def pair_id(a, b):
    """COLMAP's pair id of two image ids (order-free)."""
    a, b = (a, b) if a < b else (b, a)
    return a * MAX_IMAGE_ID + b


def ids_of_pair(pid):
    """(image_id1, image_id2), image_id1 < image_id2, of a pair id."""
    return pid // MAX_IMAGE_ID, pid % MAX_IMAGE_ID


def _blob(array, dtype):
    return np.ascontiguousarray(array, dtype=dtype).tobytes()


def _array(blob, rows, cols, dtype):
    if not rows:
        return np.zeros((0, cols), dtype)
    return np.frombuffer(blob, dtype=dtype).reshape(rows, cols)


class Database:
    """One open connection to a COLMAP database. Use it as a context manager: the writes of the
    block are one transaction, committed at its end (rolled back on an exception), and the
    connection is closed either way."""

    def __init__(self, path, create=False, timeout=60.0):
        self.path = path
        self.con = sqlite3.connect(path, timeout=timeout)
        try:
            if create:
                self.con.executescript(SCHEMA)
                self.con.commit()
            tables = {r[0] for r in self.con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        except sqlite3.DatabaseError as e:
            self.con.close()
            raise DatabaseError("%s is not a COLMAP database: %s" % (path, e))
        missing = {"cameras", "images", "keypoints", "descriptors", "matches", "two_view_geometries"} - tables
        if missing:
            self.con.close()
            raise DatabaseError("%s is not a COLMAP database: no table %s" % (path, ", ".join(sorted(missing))))

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        try:
            if kind is None:
                self.con.commit()
            else:
                self.con.rollback()
        finally:
            self.con.close()
        return False

    def close(self):
        with contextlib.suppress(sqlite3.Error):
            self.con.commit()
        self.con.close()

    # -- cameras and images ------------------------------------------------------------------
    def camera_id(self, width, height, params, model=PINHOLE):
        """The id of the camera with exactly these values, made when there is none."""
        blob = _blob(params, np.float64)
        for cid, w, h, b in self.con.execute(
                "SELECT camera_id, width, height, params FROM cameras WHERE model = ?", (model,)):
            if w == width and h == height and bytes(b) == blob:
                return cid
        cur = self.con.execute("INSERT INTO cameras (model, width, height, params, prior_focal_length) "
                               "VALUES (?, ?, ?, ?, 1)", (model, int(width), int(height), blob))
        return cur.lastrowid

    def cameras(self):
        """{camera_id: (model, width, height, params as a tuple of floats)}."""
        return {cid: (model, w, h, tuple(np.frombuffer(b, np.float64)))
                for cid, model, w, h, b in self.con.execute("SELECT camera_id, model, width, height, params FROM cameras")}

    def add_image(self, name, camera_id):
        """The new image's id (COLMAP gives ids in insertion order)."""
        try:
            return self.con.execute("INSERT INTO images (name, camera_id) VALUES (?, ?)", (name, camera_id)).lastrowid
        except sqlite3.IntegrityError as e:
            raise DatabaseError("%s: cannot add image %s: %s" % (self.path, name, e))

    def image_ids(self):
        """{name: image_id}."""
        return {name: iid for iid, name in self.con.execute("SELECT image_id, name FROM images")}

    def image_cameras(self):
        """{image_id: camera_id}."""
        return dict(self.con.execute("SELECT image_id, camera_id FROM images"))

    # -- features ----------------------------------------------------------------------------
    def write_features(self, image_id, keypoints, descriptors):
        """Keypoints (N x 2, 4 or 6 float32, COLMAP's pixel convention) and descriptors
        (N x 128 uint8) of one image, replacing any it had."""
        keypoints = np.asarray(keypoints, np.float32)
        descriptors = np.asarray(descriptors, np.uint8)
        if keypoints.ndim != 2 or keypoints.shape[1] not in (2, 4, 6):
            raise DatabaseError("keypoints of image %d: %s, not N x 2, 4 or 6" % (image_id, keypoints.shape))
        if descriptors.ndim != 2 or descriptors.shape[0] != keypoints.shape[0] or descriptors.shape[1] != 128:
            raise DatabaseError("descriptors of image %d: %s for %d keypoints, not N x 128"
                                % (image_id, descriptors.shape, keypoints.shape[0]))
        self.con.execute("INSERT OR REPLACE INTO keypoints VALUES (?, ?, ?, ?)",
                         (image_id, keypoints.shape[0], keypoints.shape[1], _blob(keypoints, np.float32)))
        self.con.execute("INSERT OR REPLACE INTO descriptors VALUES (?, ?, ?, ?)",
                         (image_id, descriptors.shape[0], descriptors.shape[1], _blob(descriptors, np.uint8)))

    def keypoints(self, image_id):
        """N x cols float32 (empty N x 2 when the image has none)."""
        row = self.con.execute("SELECT rows, cols, data FROM keypoints WHERE image_id = ?", (image_id,)).fetchone()
        return _array(row[2], row[0], row[1], np.float32) if row else np.zeros((0, 2), np.float32)

    def descriptors(self, image_id):
        row = self.con.execute("SELECT rows, cols, data FROM descriptors WHERE image_id = ?", (image_id,)).fetchone()
        return _array(row[2], row[0], row[1], np.uint8) if row else np.zeros((0, 128), np.uint8)

    def images_without_keypoints(self):
        """Names of the images extracted with no feature at all (a blank or featureless image)."""
        return {name for (name,) in self.con.execute(
            "SELECT images.name FROM images JOIN descriptors ON descriptors.image_id = images.image_id "
            "WHERE descriptors.rows = 0")}

    def images_with_features(self):
        """Names of the images with descriptors (an image with zero features counts: it was
        extracted, and extracting it again would give nothing)."""
        return {name for (name,) in self.con.execute(
            "SELECT images.name FROM images JOIN descriptors ON descriptors.image_id = images.image_id")}

    # -- matches -----------------------------------------------------------------------------
    def write_matches(self, id1, id2, matches):
        """Raw matches (M x 2 indices into id1's and id2's keypoints)."""
        m = self._ordered(id1, id2, matches)
        self.con.execute("INSERT OR REPLACE INTO matches VALUES (?, ?, ?, ?)",
                         (pair_id(id1, id2), m.shape[0], 2, _blob(m, np.uint32)))

    def write_two_view_geometry(self, id1, id2, inliers, config=CALIBRATED, F=None, E=None, H=None,
                                qvec=(1.0, 0.0, 0.0, 0.0), tvec=(0.0, 0.0, 0.0)):
        """The verified matches of a pair and its geometry. F, E, H map id1 to id2 and the pose
        (qvec, tvec) is id2's relative to id1, with id1 and id2 as given: when id1 > id2 they are
        stored for COLMAP's order (F and E transposed, H inverted, the pose inverted)."""
        F = np.zeros((3, 3)) if F is None else np.asarray(F, float)
        E = np.zeros((3, 3)) if E is None else np.asarray(E, float)
        H = np.eye(3) if H is None else np.asarray(H, float)
        if id1 > id2:
            from .. import geometry
            F, E = F.T, E.T
            H = np.linalg.inv(H) if abs(np.linalg.det(H)) > 1e-12 else np.eye(3)
            r = geometry.rotation_of(qvec)
            qvec = geometry.quaternion_of(r.T)
            tvec = tuple(-r.T @ np.asarray(tvec, float))
        m = self._ordered(id1, id2, inliers)
        self.con.execute("INSERT OR REPLACE INTO two_view_geometries VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                         (pair_id(id1, id2), m.shape[0], 2, _blob(m, np.uint32), int(config),
                          _blob(F, np.float64), _blob(E, np.float64), _blob(H, np.float64),
                          _blob(qvec, np.float64), _blob(tvec, np.float64)))

    @staticmethod
    def _ordered(id1, id2, matches):
        m = np.asarray(matches, np.uint32).reshape(-1, 2)
        return m[:, ::-1] if id1 > id2 else m

    def matches(self, id1, id2, table="matches"):
        """M x 2 indices into id1's and id2's keypoints (in the order asked), from `matches` or
        `two_view_geometries`."""
        if table not in ("matches", "two_view_geometries"):
            raise ValueError(table)
        row = self.con.execute("SELECT rows, data FROM %s WHERE pair_id = ?" % table,
                               (pair_id(id1, id2),)).fetchone()
        m = _array(row[1], row[0], 2, np.uint32) if row else np.zeros((0, 2), np.uint32)
        return m[:, ::-1] if id1 > id2 else m

    def verified_matches(self):
        """Every two-view geometry's inlier matches in one read: (pairs, matches), `pairs` an
        N x 3 int64 array of (image_id1, image_id2, count), image_id1 < image_id2, in pair id
        order, pairs without inliers left out; `matches` the sum of the counts x 2 uint32
        indices into image_id1's and image_id2's keypoints, the pairs' lists one after another."""
        rows = self.con.execute("SELECT pair_id, rows, data FROM two_view_geometries WHERE rows > 0 "
                                "ORDER BY pair_id").fetchall()
        ids = np.array([r[0] for r in rows], np.int64)
        pairs = np.stack([ids // MAX_IMAGE_ID, ids % MAX_IMAGE_ID,
                          np.array([r[1] for r in rows], np.int64)], axis=1) if rows else np.zeros((0, 3), np.int64)
        matches = np.frombuffer(b"".join(r[2] for r in rows), np.uint32).reshape(-1, 2)
        if len(matches) != pairs[:, 2].sum():
            raise DatabaseError("two_view_geometries: the inlier lists do not hold the rows they say")
        return pairs, matches

    def two_view_geometry(self, id1, id2):
        """{'rows', 'config', 'qvec', 'tvec'} of a pair in COLMAP's order, or None."""
        row = self.con.execute("SELECT rows, config, qvec, tvec FROM two_view_geometries WHERE pair_id = ?",
                               (pair_id(id1, id2),)).fetchone()
        if row is None:
            return None
        vec = lambda b, n: tuple(np.frombuffer(b, np.float64)) if b and len(b) == 8 * n else None
        return {"rows": row[0], "config": row[1], "qvec": vec(row[2], 4), "tvec": vec(row[3], 3)}

    def pair_rotations(self, min_rows=1, pairs=None):
        """[(image_id1, image_id2, (w, x, y, z))]: the relative rotation (image_id2's relative to
        image_id1's, image_id1 < image_id2) of the two-view geometries with at least `min_rows`
        inliers whose relative pose was estimated (a unit qvec and a non-zero tvec: COLMAP's
        matcher leaves them zero where it estimated none); only those of `pairs` ((id, id), either
        order; read one by one) when given."""
        sql = "SELECT pair_id, qvec, tvec FROM two_view_geometries WHERE rows >= ?"
        if pairs is None:
            rows = self.con.execute(sql, (int(min_rows),)).fetchall()
        else:
            rows = [r for a, b in pairs
                    for r in self.con.execute(sql + " AND pair_id = ?", (int(min_rows), pair_id(a, b))).fetchall()]
        out = []
        for pid, q, t in rows:
            if not q or len(q) != 32 or not t or len(t) != 24:
                continue
            qvec, tvec = np.frombuffer(q, np.float64), np.frombuffer(t, np.float64)
            if not (np.all(np.isfinite(qvec)) and abs(float(qvec @ qvec) - 1.0) < 1e-6 and np.any(tvec != 0.0)):
                continue
            a, b = ids_of_pair(pid)
            out.append((a, b, tuple(float(v) for v in qvec)))
        return out

    def geometry_pairs(self, verified_only=False):
        """{(image_id1, image_id2)} of the pairs with a two-view geometry (matched and verified
        or found not to verify); with verified_only, those with at least one inlier."""
        sql = "SELECT pair_id FROM two_view_geometries" + (" WHERE rows > 0" if verified_only else "")
        return {ids_of_pair(pid) for (pid,) in self.con.execute(sql)}

    def images_with_features_among(self, image_ids):
        """The ids among `image_ids` that have descriptors: only those rows are read."""
        return {iid for iid in image_ids
                if self.con.execute("SELECT 1 FROM descriptors WHERE image_id = ?", (int(iid),)).fetchone()}

    def inlier_counts_among(self, pairs):
        """{(image_id1, image_id2): inlier matches} of those of `pairs` ((id, id), either order)
        that have a two-view geometry: only those rows are read."""
        out = {}
        for a, b in pairs:
            row = self.con.execute("SELECT rows FROM two_view_geometries WHERE pair_id = ?", (pair_id(a, b),)).fetchone()
            if row is not None:
                out[(min(a, b), max(a, b))] = row[0]
        return out

    def inlier_counts(self):
        """{(image_id1, image_id2): inlier matches} of every pair with a two-view geometry."""
        return {ids_of_pair(pid): rows for pid, rows in self.con.execute("SELECT pair_id, rows FROM two_view_geometries")}

    def keep_pairs(self, pairs):
        """Deletes the matches and two-view geometries of every pair not in `pairs` ((id, id)
        or (name, name)); returns how many pairs are kept."""
        ids = self.image_ids()
        keep = {pair_id(*(ids[x] if isinstance(x, str) else x for x in p)) for p in pairs}
        for table in ("matches", "two_view_geometries"):
            gone = [(r,) for (r,) in self.con.execute("SELECT pair_id FROM %s" % table) if r not in keep]
            self.con.executemany("DELETE FROM %s WHERE pair_id = ?" % table, gone)
        return len(keep)

    def matched_names(self):
        """[(name, name)] of the pairs with raw matches (a matcher's choice of pairs)."""
        names = {iid: name for name, iid in self.image_ids().items()}
        return [(names[a], names[b]) for a, b in (ids_of_pair(pid) for (pid,) in
                                                  self.con.execute("SELECT pair_id FROM matches"))]

    def delete_matches(self):
        """Every raw match and two-view geometry (features and images stay)."""
        self.con.execute("DELETE FROM matches")
        self.con.execute("DELETE FROM two_view_geometries")

    def counts(self):
        """How many cameras, images, images with features, matched and verified pairs."""
        one = lambda sql: self.con.execute(sql).fetchone()[0]
        return {"cameras": one("SELECT COUNT(*) FROM cameras"), "images": one("SELECT COUNT(*) FROM images"),
                "images_with_features": one("SELECT COUNT(*) FROM descriptors"),
                "pairs_matched": one("SELECT COUNT(*) FROM matches"),
                "pairs_with_geometry": one("SELECT COUNT(*) FROM two_view_geometries"),
                "pairs_verified": one("SELECT COUNT(*) FROM two_view_geometries WHERE rows > 0")}


def open_database(path, create=False):
    """A Database for a `with` block: `with open_database(p) as db: ...`."""
    return Database(path, create=create)
