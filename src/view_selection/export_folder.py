"""A folder written by the node's ~export or by select_views: selection.json, pairs.txt and,
somewhere, the keyframe images."""
import json
import os

from .keyframes import Keyframe


class ExportError(Exception):
    pass


class ExportFolder:
    def __init__(self, folder):
        self.folder = os.path.abspath(folder)
        try:
            with open(os.path.join(self.folder, "selection.json")) as f:
                self.selection = json.load(f)
        except (OSError, ValueError) as e:
            raise ExportError("%s: no readable selection.json (%s)" % (self.folder, e))
        try:
            self.keyframes = [Keyframe.from_json(i, k) for i, k in enumerate(self.selection["keyframes"])]
        except (KeyError, TypeError, ValueError) as e:
            raise ExportError("%s/selection.json: a keyframe without its pose or intrinsics (%s)" % (self.folder, e))
        self.pairs_txt = os.path.join(self.folder, "pairs.txt")
        if not os.path.isfile(self.pairs_txt):
            raise ExportError("%s has no pairs.txt" % self.folder)
        with open(self.pairs_txt) as f:
            self.pairs = [tuple(line.split()[:2]) for line in f if len(line.split()) >= 2]

    def image_root(self, override=None):
        """The folder the keyframe image names are relative to: `override`, or selection.json's
        params image_path, relative to params dataset (select_views) or to the export folder."""
        if override:
            return os.path.abspath(override)
        params = self.selection.get("params", {})
        rel = params.get("image_path", "")
        candidates = []
        if params.get("dataset"):
            candidates.append(os.path.join(params["dataset"], rel))
        candidates.append(os.path.join(self.folder, rel or "."))
        names = [k.name for k in self.keyframes]
        for c in candidates:
            if names and all(os.path.isfile(os.path.join(c, n)) for n in names):
                return os.path.abspath(c)
        raise ExportError("cannot find the keyframe images (looked in %s); export them with "
                          "~save_keyframe_images, or give --image-path" % ", ".join(candidates))

    def initial_pair(self):
        """The image names of the selection's initial pair (s, C_s[0]), or None."""
        initial = self.selection.get("initial_pair")
        if not initial or any(v >= len(self.keyframes) for v in initial):
            return None
        return self.keyframes[initial[0]].name, self.keyframes[initial[1]].name
