"""What a project's database holds, kept in memory: image names and ids, their cameras, which
images have features, which pairs have a two-view geometry and with how many inliers.

Read whole once (the first time it is asked, so also after a restart), then kept current by the
steps that write the database: each tells it what it wrote, or asks it to read back only the
rows of what it worked on. So a batch of the bridge costs the work of what changed, not a read
of whole tables that grow with the session (issue 34: at 3,000 keyframes and 20,000 pairs the
per-batch reads of image ids, matched pairs and inlier counts were O(session)).

Only the project's own steps write the database while it runs (COLMAP's commands are its
children, run on lists the project gives them); anything else that changes it must call
ColmapProject.forget() so that it is read again.
"""
from ..keyframes import pair_of


class Catalogue:
    def __init__(self, database):
        """database: an open colmap.database.Database (read whole, once)."""
        self.ids = database.image_ids()                       # name -> image id
        self.names = {iid: name for name, iid in self.ids.items()}
        self.image_cameras = database.image_cameras()         # image id -> camera id
        self.cameras = database.cameras()                     # camera id -> (model, w, h, params)
        self.with_features = set(database.images_with_features())  # names
        self.inliers = {}                                     # (name, name) sorted -> inlier matches
        for (a, b), rows in database.inlier_counts().items():
            if a in self.names and b in self.names:
                self.inliers[pair_of(self.names[a], self.names[b])] = rows
        # Verified pairs (ids, a < b) not yet taken by take_new_verified(): all of them at first.
        self.new_verified = [(min(self.ids[a], self.ids[b]), max(self.ids[a], self.ids[b]))
                             for (a, b), n in sorted(self.inliers.items()) if n > 0]

    # -- images ------------------------------------------------------------------------------
    def image_added(self, name, iid, camera_id, camera=None):
        self.ids[name], self.names[iid] = iid, name
        self.image_cameras[iid] = camera_id
        if camera is not None:
            self.cameras[camera_id] = camera

    def read_features(self, database, names):
        """Reads back whether these images have features (after a step that extracted them)."""
        ids = {self.ids[n]: n for n in names if n in self.ids}
        have = database.images_with_features_among(list(ids))
        for iid, name in ids.items():
            if iid in have:
                self.with_features.add(name)

    def features_written(self, names):
        self.with_features.update(names)

    # -- pairs -------------------------------------------------------------------------------
    def read_pairs(self, database, pairs):
        """Reads back the two-view geometries of these pairs (names) after a step matched them."""
        ids = {}
        for a, b in pairs:
            if a in self.ids and b in self.ids:
                ia, ib = self.ids[a], self.ids[b]
                ids[(min(ia, ib), max(ia, ib))] = pair_of(a, b)
        for key, rows in database.inlier_counts_among(list(ids)).items():
            self.geometry_written(ids[key], rows)

    def geometry_written(self, pair, rows):
        """A pair (names) got a two-view geometry with `rows` inliers."""
        pair = pair_of(*pair)
        before = self.inliers.get(pair)
        self.inliers[pair] = int(rows)
        if rows > 0 and not before:
            ia, ib = self.ids[pair[0]], self.ids[pair[1]]
            self.new_verified.append((min(ia, ib), max(ia, ib)))

    def take_new_verified(self):
        """The verified pairs (image ids) not taken before, in the order they verified."""
        out, self.new_verified = self.new_verified, []
        return out
