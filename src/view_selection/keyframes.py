"""A keyframe as the node names it: id, image name, stamp, camera-to-world pose, intrinsics.

Built from a view_selection/KeyframeInfo message (the pair stream, ~get_selection) or from a
keyframe of selection.json (~export, select_views). Both give the same object, so the bridge
online and colmap_from_selection offline build the same project.
"""
import math


class Keyframe:
    __slots__ = ("id", "name", "stamp", "position", "orientation", "intrinsics", "width", "height", "revisit_of")

    def __init__(self, id, name, stamp, position, orientation, intrinsics, width, height, revisit_of=-1):
        """orientation: camera-to-world (w, x, y, z); intrinsics: (fx, fy, cx, cy) in pixels.
        revisit_of: -1, or the id of an earlier keyframe that the frames just before this one
        were recognised from their images to revisit (the node's ~revisit_registration): a pair
        across drift that the poses do not show (matching/loops.py proposes it)."""
        self.id, self.name, self.stamp = int(id), str(name), float(stamp)
        self.revisit_of = int(revisit_of) if 0 <= int(revisit_of) < self.id else -1
        self.position = tuple(float(v) for v in position)
        self.orientation = tuple(float(v) for v in orientation)
        self.intrinsics = tuple(float(v) for v in intrinsics)[:4]
        self.width, self.height = int(width), int(height)
        if len(self.position) != 3 or len(self.orientation) != 4 or len(self.intrinsics) != 4:
            raise ValueError("keyframe %d (%s): a pose needs 3 + 4 values and intrinsics 4" % (self.id, self.name))
        if not all(math.isfinite(v) for v in self.position + self.orientation + self.intrinsics):
            raise ValueError("keyframe %d (%s): its pose or intrinsics are not finite" % (self.id, self.name))

    def __repr__(self):
        return "Keyframe(%d, %r)" % (self.id, self.name)

    def colmap_camera_params(self):
        """(fx, fy, cx, cy) in COLMAP's pixel convention: ROS's camera_info (and OpenCV) put the
        top-left pixel's centre at (0, 0), COLMAP at (0.5, 0.5), so the principal point moves by
        half a pixel. Keypoints move the same way (features/sift.py; COLMAP's own extractor
        writes them so), and the two agree."""
        fx, fy, cx, cy = self.intrinsics
        return fx, fy, cx + 0.5, cy + 0.5

    def camera_key(self):
        """Keyframes with the same key share one COLMAP camera."""
        return self.intrinsics, self.width, self.height

    @staticmethod
    def from_msg(k):
        """A view_selection/KeyframeInfo (or anything with its fields)."""
        p, o = k.pose.position, k.pose.orientation
        return Keyframe(k.id, k.image_name, k.stamp.to_sec(), (p.x, p.y, p.z), (o.w, o.x, o.y, o.z),
                        list(k.intrinsics)[:4], k.width, k.height, getattr(k, "revisit_of", -1))

    @staticmethod
    def from_json(index, k):
        """A keyframe of selection.json: position, orientation_xyzw, intrinsics (fx fy cx cy w h)."""
        x, y, z, w = k["orientation_xyzw"]
        intr = k["intrinsics"]
        return Keyframe(k.get("id", index), k["image"], k.get("stamp", 0.0), k["position"], (w, x, y, z), intr[:4],
                        intr[4] if len(intr) > 4 else 0, intr[5] if len(intr) > 5 else 0, k.get("revisit_of", -1))

    def to_json(self):
        w, x, y, z = self.orientation
        out = {"id": self.id, "image": self.name, "stamp": self.stamp, "position": list(self.position),
               "orientation_xyzw": [x, y, z, w], "intrinsics": list(self.intrinsics) + [self.width, self.height]}
        if self.revisit_of >= 0:
            out["revisit_of"] = self.revisit_of
        return out


def pair_of(a, b):
    """A pair of image names as the project keys it: sorted."""
    return (a, b) if a <= b else (b, a)


def continuity_pairs(keyframes):
    """Each keyframe with the one before it (by id: the order they were accepted in), as names.

    The selection prefers wide, well-conditioned pairs; the known-pose model's points also need
    tracks that continue from one keyframe to the next (docs/live.md: +11% pairs, +42% points on
    the kitchen). Matched beside the selection's pairs; the selection itself is unchanged."""
    ordered = sorted(keyframes, key=lambda k: k.id)
    return [pair_of(a.name, b.name) for a, b in zip(ordered, ordered[1:])]


class ContinuityChain:
    """continuity_pairs(keyframes) kept up to date as keyframes are appended: a batch adds the new
    keyframes' pairs (issue 34: its work is what changed), and the chain is built again only when
    a keyframe does not come after the last one (another session, or ids out of order)."""

    def __init__(self):
        self.pairs = set()
        self.last = None  # the keyframe with the largest id so far

    def rebuild(self, keyframes):
        self.pairs = set(continuity_pairs(keyframes))
        self.last = max(keyframes, key=lambda k: k.id) if keyframes else None

    def extend(self, new):
        """Adds the pairs of `new` (appended, in their order) and returns them (a list); None,
        changing nothing, when one of them does not come after the one before it."""
        chain = ([self.last] if self.last is not None else []) + list(new)
        if any(b.id <= a.id for a, b in zip(chain, chain[1:])):
            return None
        added = [pair_of(a.name, b.name) for a, b in zip(chain, chain[1:])]
        self.pairs.update(added)
        if chain:
            self.last = chain[-1]
        return added
