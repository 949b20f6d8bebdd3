"""A COLMAP 3.8 project folder kept by running COLMAP's own commands:

  DIR/images/       the keyframe images (the node writes them; colmap_from_selection links them)
  DIR/database.db   cameras, images, features, matches, verified two-view geometries
  DIR/sparse/0/     the model (known poses and point_triangulator, or the mapper)
  DIR/ledger.txt    every image extracted and pair matched, once, in order (and what the bridge
                    gave up, and matched pairs the node took back), each line with its time
  DIR/colmap.log    every COLMAP command and its output

Every step reads the database first, so nothing is extracted or matched twice, also across
restarts. Shared by colmap_bridge (online) and colmap_from_selection (offline).
"""
import json
import os
import shutil
import tempfile
import time

from ..keyframes import pair_of
from .. import geometry
from . import database as db
from . import durable
from . import model as colmap_model
from .catalogue import Catalogue
from .process import Colmap, ColmapError


class ProjectError(Exception):
    """A project that cannot be kept: an unusable folder, COLMAP missing or failing (timed_out:
    a COLMAP command was killed at its time limit; out_of_time: the project's deadline passed,
    which is no item's fault)."""

    def __init__(self, message, timed_out=False, out_of_time=False):
        super().__init__(message)
        self.timed_out, self.out_of_time = timed_out, out_of_time


class Timeouts:
    """Seconds a COLMAP call may take: `base` plus so much per image or pair it works on. Bounded
    so a hung COLMAP never holds the project for ever; generous so a slow machine still finishes
    (COLMAP 3.8 on 2 cores: about 0.2 s an image extracted, 0.2 s a pair matched)."""

    def __init__(self, base=120.0, per_image=10.0, per_pair=5.0):
        self.base, self.per_image, self.per_pair = float(base), float(per_image), float(per_pair)

    def images(self, n):
        return self.base + self.per_image * n

    def pairs(self, n):
        return self.base + self.per_pair * n


def write_json_atomically(path, data):
    """`data` as JSON in `path`: written beside it, fsynced, renamed over it, the folder fsynced
    (durable.write_atomically: the old report or the new, also after a power loss)."""
    durable.write_atomically(path, json.dumps(data, indent=2, sort_keys=True, default=str) + "\n")


replace_folder = durable.replace_folder  # sparse/0 swapped in one step, never absent


class ColmapProject:
    def __init__(self, root, colmap="colmap", threads=-1, image_dir=None, timeouts=None):
        self.root = os.path.abspath(root)
        self.images = os.path.abspath(image_dir) if image_dir else os.path.join(self.root, "images")
        self.database = os.path.join(self.root, "database.db")
        self.log_path = os.path.join(self.root, "colmap.log")
        self.colmap = Colmap(colmap, self.log_path)
        self.threads = str(int(threads))
        self.timeouts = timeouts or Timeouts()
        self.init_pair = None  # (name, name): the mapper starts from these two images
        self.deadline = None  # time.monotonic() by which every COLMAP call must be done, or None
        self.seconds = self.colmap.seconds  # per stage: extraction, matching, model
        self._catalogue = None  # what the database holds (catalogue.py), read at the first use
        for stage in ("extraction", "matching", "model"):
            self.seconds.setdefault(stage, 0.0)

    # -- the folder and the database --------------------------------------------------------
    def open(self):
        """Makes the folders and the database (COLMAP's schema) when missing; checks COLMAP."""
        try:
            os.makedirs(self.images, exist_ok=True)
            os.makedirs(os.path.join(self.root, "sparse"), exist_ok=True)
            probe = tempfile.NamedTemporaryFile(dir=self.root, prefix=".write_test", delete=True)
            probe.close()
        except OSError as e:
            raise ProjectError("cannot use the project folder %s: %s" % (self.root, e.strerror or e))
        if not self.colmap.available():
            raise ProjectError("'%s' not found: install COLMAP (apt-get install colmap)" % self.colmap.executable)
        try:
            with self.db(create=True):
                pass
        except db.DatabaseError as e:
            raise ProjectError(str(e))

    def db(self, create=False):
        """The project's database, for a `with` block (one transaction, closed after)."""
        return db.Database(self.database, create=create)

    def catalogue(self):
        """What the database holds, in memory (catalogue.py): read whole once, then kept current
        by the steps that write it."""
        if self._catalogue is None:
            with self.db() as d:
                self._catalogue = Catalogue(d)
        return self._catalogue

    def forget(self):
        """The database was changed by something other than this project's steps: read it again."""
        self._catalogue = None

    def run(self, args, stage, timeout):
        """A COLMAP command, within `timeout` and within the project's deadline when one is set
        (a finish at shutdown has only so long)."""
        if self.cancelled:
            raise ProjectError("'%s' (%s) not started: the project's work was cancelled" % (args[0], stage))
        cut = False
        if self.deadline is not None:
            left = self.deadline - time.monotonic()
            if left <= 1.0:
                raise ProjectError("no time left for '%s' (%s)" % (args[0], stage), out_of_time=True)
            cut, timeout = left < timeout, min(timeout, left)
        try:
            return self.colmap.run(args, stage, timeout)
        except ColmapError as e:
            raise ProjectError(str(e), timed_out=e.timed_out, out_of_time=e.timed_out and cut)

    def check_deadline(self, stage):
        """Raises ProjectError (out_of_time) once the project's deadline has passed: the in-process
        loops (SIFT, guided matching, the live model) call it for each item, as run() bounds a
        COLMAP command (one clock read)."""
        if self.deadline is not None and time.monotonic() >= self.deadline:
            raise ProjectError("out of time in %s: the finish's budget at shutdown is spent" % stage,
                               out_of_time=True)

    @property
    def cancelled(self):
        """Set by cancel(), kept until the caller clears it: no COLMAP command runs meanwhile
        (the flag is the Colmap's, so a cancel between a check and a start is not lost)."""
        return self.colmap.cancelled

    @cancelled.setter
    def cancelled(self, value):
        self.colmap.cancelled = bool(value)

    def cancel(self):
        """Kills the COLMAP command running now (from another thread), and refuses to start
        another until `cancelled` is cleared; the one killed raises ProjectError."""
        self.colmap.cancel()

    def link_images(self, keyframes, source):
        """DIR/images as the node writes it, from the folder `source` the keyframes' image names
        are relative to: linked, not copied, where the file system allows."""
        for k in keyframes:
            target = os.path.join(self.images, k.name)
            os.makedirs(os.path.dirname(target), exist_ok=True)
            try:
                os.link(os.path.join(source, k.name), target)
            except OSError:
                shutil.copyfile(os.path.join(source, k.name), target)

    def has_image(self, name):
        return os.path.isfile(os.path.join(self.images, name))

    def ledger(self, what, items):
        """DIR/ledger.txt: every image extracted and every pair matched, one line each when the
        database has it, in order (what was done when; each appears once)."""
        if not items:
            return
        stamp = "%.3f" % time.time()
        durable.append_durably(os.path.join(self.root, "ledger.txt"),
                               "".join("%s %s %s\n" % (stamp, what, item) for item in items))

    def ledger_items(self, what):
        """The items DIR/ledger.txt has under `what` (e.g. "skipped-image": names;
        "skipped-pair": "name name"), in order, each once; a last line a crash cut short is
        left out."""
        path = os.path.join(self.root, "ledger.txt")
        if not os.path.exists(path):
            return []
        with open(path) as f:
            lines = f.read().split("\n")[:-1]  # the text after the last newline may be torn
        seen, out = set(), []
        for line in lines:
            parts = line.split(" ", 2)
            if len(parts) == 3 and parts[1] == what and parts[2] not in seen:
                seen.add(parts[2])
                out.append(parts[2])
        return out

    def image_ids(self):
        return dict(self.catalogue().ids)

    def register(self, keyframes):
        """Rows in `images` for keyframes the database does not have yet, in id order (so the
        image ids, and the direction each pair is matched in, do not depend on when images
        arrived or on a restart), each with the PINHOLE camera of its intrinsics (in COLMAP's
        pixel convention, Keyframe.colmap_camera_params)."""
        cat = self.catalogue()
        new = sorted((k for k in keyframes if k.name not in cat.ids), key=lambda k: k.id)
        if not new:
            return
        with self.db() as d:
            added, names = [], set()
            for k in new:
                if k.name in names:  # the same image twice in the list
                    continue
                names.add(k.name)
                cid = d.camera_id(k.width, k.height, k.colmap_camera_params())
                added.append((k.name, d.add_image(k.name, cid), cid))
            cameras = d.cameras() if any(cid not in cat.cameras for _, _, cid in added) else {}
        for name, iid, cid in added:  # after the commit: the catalogue holds what the database does
            cat.image_added(name, iid, cid, cameras.get(cid))

    def extracted(self, refresh=()):
        """Names of the images with features, as a live set (not a copy: it grows with the
        session; the caller must not change it, and copies it to keep it); `refresh`: names whose
        rows are read back first (after a step that extracted them)."""
        cat = self.catalogue()
        if refresh:
            with self.db() as d:
                cat.read_features(d, refresh)
        return cat.with_features

    def matched(self, refresh=()):
        """Pairs (name, name), sorted within, that were matched (verified or not), as a live
        read-only view (set operations and `in` work on it; copy it to keep it); `refresh`:
        pairs whose rows are read back first (after a step that matched them)."""
        cat = self.catalogue()
        if refresh:
            with self.db() as d:
                cat.read_pairs(d, refresh)
        return cat.inliers.keys()  # a view, not a copy: it grows with the session

    def inlier_counts(self):
        """{(name, name): inlier matches} of the pairs matched (0: matched, not verified)."""
        return dict(self.catalogue().inliers)

    def verified_count(self):
        return sum(1 for n in self.catalogue().inliers.values() if n > 0)

    # -- COLMAP's own extraction and matching -------------------------------------------------
    def extract(self, keyframes):
        """SIFT features (feature_extractor) of the keyframes whose images are in DIR/images and
        that have none; returns how many were asked for."""
        self.register(keyframes)
        done = self.extracted()
        todo = [k for k in keyframes if k.name not in done and os.path.isfile(os.path.join(self.images, k.name))]
        if not todo:
            return 0
        listing = os.path.join(self.root, ".extract_list.txt")
        with open(listing, "w") as f:
            f.write("".join(k.name + "\n" for k in todo))
        try:
            self.run(["feature_extractor", "--database_path", self.database, "--image_path", self.images,
                      "--image_list_path", listing, "--ImageReader.camera_model", "PINHOLE",
                      "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", self.threads], "extraction",
                     self.timeouts.images(len(todo)))
        finally:  # also what a run that failed half-way wrote
            now = self.extracted(refresh=[k.name for k in todo])
        self.ledger("extracted", [k.name for k in todo if k.name in now])
        return len(todo)

    def match(self, pairs):
        """Matches and verifies (matches_importer) the pairs (name, name) not matched yet whose
        images have features; returns how many were matched now."""
        done = self.matched()
        have = self.extracted()
        todo = sorted({pair_of(*p) for p in pairs} - done)
        todo = [p for p in todo if p[0] in have and p[1] in have]
        if not todo:
            return 0
        listing = os.path.join(self.root, ".match_list.txt")
        with open(listing, "w") as f:
            f.write("".join("%s %s\n" % p for p in todo))
        try:
            self.run(["matches_importer", "--database_path", self.database, "--match_list_path", listing,
                      "--match_type", "pairs", "--SiftMatching.use_gpu", "0",
                      "--SiftMatching.num_threads", self.threads], "matching", self.timeouts.pairs(len(todo)))
        finally:  # also what a run that failed half-way wrote
            now = self.matched(refresh=todo)
        self.ledger("matched", ["%s %s" % p for p in todo if p in now])
        return len(todo)

    # -- models ------------------------------------------------------------------------------
    def known_poses(self, keyframes):
        """The model point_triangulator starts from: the keyframes at their poses (the
        database's image and camera ids), no points."""
        cat = self.catalogue()
        ids, cams, cameras = cat.ids, cat.image_cameras, cat.cameras
        model = colmap_model.Model()
        for k in keyframes:
            if k.name not in ids:
                continue
            iid = ids[k.name]
            cid = cams[iid]
            mid, w, h, params = cameras[cid]
            model.cameras[cid] = colmap_model.Camera(cid, colmap_model.CAMERA_MODELS[mid][0], w, h, params)
            q, t = geometry.world_to_camera(k.position, k.orientation)
            model.images[iid] = colmap_model.Image(iid, q, t, cid, k.name)
        return model

    def known_pose_model(self, keyframes, output=None):
        """DIR/sparse/0: the keyframes at their poses, points from point_triangulator with the
        poses, focal lengths and principal points held fixed."""
        output = output or os.path.join(self.root, "sparse", "0")
        work = tempfile.mkdtemp(prefix=".model_", dir=os.path.join(self.root, "sparse"))
        try:
            given, made = os.path.join(work, "given"), os.path.join(work, "made")
            os.makedirs(made)
            colmap_model.write_model(self.known_poses(keyframes), given, binary=False)
            self.run(["point_triangulator", "--database_path", self.database, "--image_path", self.images,
                      "--input_path", given, "--output_path", made,
                      "--Mapper.ba_refine_focal_length", "0", "--Mapper.ba_refine_principal_point", "0",
                      "--Mapper.ba_refine_extra_params", "0", "--Mapper.num_threads", self.threads], "model",
                     self.timeouts.images(len(keyframes)))
            replace_folder(made, output)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        return output

    def write_model(self, model, output=None):
        """A colmap.model.Model into DIR/sparse/0 (binary), replacing the one there in one step."""
        output = output or os.path.join(self.root, "sparse", "0")
        work = tempfile.mkdtemp(prefix=".write_", dir=os.path.join(self.root, "sparse"))
        try:
            colmap_model.write_model(model, os.path.join(work, "made"), binary=True)
            replace_folder(os.path.join(work, "made"), output)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        return output

    def poses_only_model(self, keyframes, output=None):
        """DIR/sparse/0 with the keyframes at their poses and no points: what is left when no
        pair verified, or point_triangulator failed (it aborts on a database without matches)."""
        return self.write_model(self.known_poses(keyframes), output)

    def mapper_model(self, seed=0, output=None):
        """DIR/sparse/0: COLMAP's mapper from scratch (its largest model)."""
        output = output or os.path.join(self.root, "sparse", "0")
        work = tempfile.mkdtemp(prefix=".mapper_", dir=os.path.join(self.root, "sparse"))
        try:
            with self.db() as d:
                n = d.counts()["images"]
                ids = d.image_ids()
            args = ["mapper", "--database_path", self.database, "--image_path", self.images,
                    "--output_path", work, "--Mapper.num_threads", self.threads, "--random_seed", str(seed)]
            if self.init_pair and all(name in ids for name in self.init_pair):
                args += ["--Mapper.init_image_id1", str(ids[self.init_pair[0]]),
                         "--Mapper.init_image_id2", str(ids[self.init_pair[1]])]
            self.run(args, "model", self.timeouts.images(n))
            models = sorted(d for d in os.listdir(work) if d.isdigit())
            if not models:
                raise ProjectError("the mapper made no model; see %s" % self.log_path)
            best = max(models, key=lambda m: len(colmap_model.read_model(os.path.join(work, m)).images))
            replace_folder(os.path.join(work, best), output)
        finally:
            shutil.rmtree(work, ignore_errors=True)
        return output
