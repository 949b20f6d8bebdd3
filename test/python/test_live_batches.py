"""The bridge's batches on a real project database (no COLMAP, no ROS): each batch looks only at
the keyframes that changed since the one before (live/changes.py), and what changed still reaches
the database and the live model, as when every batch went through the whole session."""
import os

import numpy as np

from view_selection import geometry
from view_selection.colmap.project import ColmapProject
from view_selection.keyframes import Keyframe
from view_selection.live.work import LiveWork

N_FEATURES = 30


def keyframe(i, x=None):
    return Keyframe(i, "%03d.png" % i, float(i), (0.1 * i if x is None else x, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                    (300.0, 300.0, 160.0, 120.0), 320, 240)


class Backend:
    """Writes features and verified matches as the pose-guided backend does, without images."""

    def __init__(self, project):
        self.project, self.arrived = project, set()

    def register(self, keyframes):
        self.project.register(keyframes)

    def has_image(self, name):
        return name in self.arrived

    def extracted(self, refresh=()):
        return self.project.extracted(refresh)

    def matched(self, refresh=()):
        return self.project.matched(refresh)

    def extract(self, keyframes):
        ids = self.project.image_ids()
        rng = np.random.default_rng(len(keyframes))
        with self.project.db() as d:
            for k in keyframes:
                kp = np.column_stack([rng.uniform(0, 320, N_FEATURES), rng.uniform(0, 240, N_FEATURES),
                                      np.ones(N_FEATURES), np.zeros(N_FEATURES)]).astype(np.float32)
                d.write_features(ids[k.name], kp, np.zeros((N_FEATURES, 128), np.uint8))
        self.project.catalogue().features_written([k.name for k in keyframes])

    def match(self, pairs):
        ids = self.project.image_ids()
        with self.project.db() as d:
            for a, b in pairs:
                m = np.column_stack([np.arange(20), np.arange(20)])
                d.write_matches(ids[a], ids[b], m)
                d.write_two_view_geometry(ids[a], ids[b], m)
        for p in pairs:
            self.project.catalogue().geometry_written(p, 20)


def session(tmp_path):
    project = ColmapProject(str(tmp_path / "project"))
    os.makedirs(project.images, exist_ok=True)
    with project.db(create=True):
        pass
    backend = Backend(project)
    return project, backend, LiveWork(project, continuity=True, backend=backend)


def batch(work, keyframes):
    work.extract(keyframes)
    work.match(keyframes, set())
    work.feed_model(keyframes)


def pose_in_model(work, project, k):
    image = work.model.images[project.image_ids()[k.name]]
    return geometry.centre_of(geometry.quaternion_of(image.r), image.t)


def test_a_moved_keyframe_reaches_the_live_model_and_one_that_waited_gets_its_keypoints(tmp_path):
    project, backend, work = session(tmp_path)
    kfs = [keyframe(i) for i in range(6)]
    backend.arrived = {k.name for k in kfs} - {"003.png"}
    batch(work, kfs)
    ids = project.image_ids()
    assert len(work.model.images[ids["002.png"]].keypoints) == N_FEATURES
    assert ids["003.png"] not in work.model.images or not len(work.model.images[ids["003.png"]].keypoints)
    for _ in range(3):  # batches with nothing new: nothing is lost meanwhile
        batch(work, kfs)
    kfs = kfs[:2] + [keyframe(2, x=5.0)] + kfs[3:] + [keyframe(6)]  # keyframe 2 moved, 6 is new
    backend.arrived |= {"003.png", "006.png"}
    batch(work, kfs)
    assert np.allclose(pose_in_model(work, project, kfs[2]), (5.0, 0.0, 0.0))
    assert np.allclose(pose_in_model(work, project, kfs[4]), (0.4, 0.0, 0.0))
    for name in ("003.png", "006.png"):
        assert len(work.model.images[ids.get(name) or project.image_ids()[name]].keypoints) == N_FEATURES
    assert set(project.matched()) == {(a.name, b.name) for a, b in zip(kfs, kfs[1:])}  # continuity
    assert work.unfed == {} and work.unextracted == {}
