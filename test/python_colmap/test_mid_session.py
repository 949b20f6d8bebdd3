"""Bad input in the middle of a session, through the bridge's work (LiveWork with the pose-guided
backend, the real COLMAP for the fallback), without ROS (issue 34): a loop closure that moves
earlier keyframes, a pose that jumps (a SLAM glitch, put right by a later message), and a keyframe
whose image never arrives. The live model takes the moved poses (its points follow them), nothing
already matched is matched again, and the finish names what is missing and builds the rest."""
import json
import os
import shutil

import numpy as np

from conftest import walk_selection
from view_selection.colmap.model import read_model
from view_selection.colmap.project import ColmapProject
from view_selection.export_folder import ExportFolder
from view_selection.geometry import centre_of
from view_selection.keyframes import Keyframe
from view_selection.live.work import LiveWork
from view_selection.matching.backend import PoseGuidedBackend

SHIFT = np.array([0.03, -0.02, 0.01])  # [m] the loop closure's correction of the first half
JUMP = np.array([0.5, 0.0, -0.3])  # [m] a glitch of one keyframe's pose in the second half


def moved(k, shift):
    return Keyframe(k.id, k.name, k.stamp, tuple(np.asarray(k.position) + shift), k.orientation, k.intrinsics,
                    k.width, k.height)


def ledger_items(project, what):
    with open(os.path.join(project.root, "ledger.txt")) as f:
        return [line.split(None, 2)[2].strip() for line in f if line.split()[1:2] == [what]]


def test_a_loop_closure_and_a_missing_image_mid_session(tmp_path):
    _, selection = walk_selection(tmp_path, 90)
    export = ExportFolder(str(selection))
    keyframes, pairs = export.keyframes, export.pairs
    assert len(keyframes) == 15
    project = ColmapProject(str(tmp_path / "project"), threads=2)
    os.makedirs(project.images)
    missing = keyframes[-1].name  # its image never arrives
    for k in keyframes:
        if k.name != missing:
            shutil.copyfile(os.path.join(export.image_root(), k.name), os.path.join(project.images, k.name))
    project.open()
    work = LiveWork(project, backend=PoseGuidedBackend(project))

    # The first half of the session, matched and in the live model.
    half = keyframes[:8]
    first = [p for p in pairs if p[0] in {k.name for k in half} and p[1] in {k.name for k in half}]
    work.extract(half)
    work.match_all(half, first)
    work.feed_model(half)
    matched_before = set(ledger_items(project, "matched"))
    assert matched_before and work.model.points
    centres_before = {work.model.images[i].name: work.model.images[i].centre.copy() for i in work.model.images}
    triangulated = work.model.observations_triangulated

    # A loop closure moves the first half; the rest of the session comes, one keyframe with its
    # pose 0.58 m off (its pairs cannot be guided by that pose: COLMAP's matcher verifies them),
    # and the next message puts that pose right.
    corrected = [moved(k, SHIFT) for k in half] + keyframes[8:]
    jumped = corrected[10].name
    glitch = corrected[:10] + [moved(corrected[10], JUMP)] + corrected[11:]
    work.extract(glitch)
    work.match_all(glitch, pairs)
    work.feed_model(glitch)
    iid = project.image_ids()[jumped]
    assert np.allclose(work.model.images[iid].centre, np.asarray(corrected[10].position) + JUMP, atol=1e-9)
    work.match_all(corrected, pairs)
    work.feed_model(corrected)
    assert np.allclose(work.model.images[iid].centre, corrected[10].position, atol=1e-9)  # put right
    assert {p for p in pairs if jumped in p and missing not in p} <= set(project.matched())
    for k in half:
        iid = project.image_ids()[k.name]
        assert np.allclose(work.model.images[iid].centre, centres_before[k.name] + SHIFT, atol=1e-9), k.name
    assert work.model.observations_triangulated > triangulated  # the moved images' tracks made again
    matched = ledger_items(project, "matched")
    assert len(matched) == len(set(matched)), "a pair was matched twice"
    assert matched_before <= set(matched)

    report = work.build_model(corrected, pairs)
    assert report["images_missing"] == [missing]
    lost = {x["pair"]: x["reason"] for x in report["pairs_lost"]}
    assert lost and all(missing in pair.split() for pair in lost)
    assert all(reason == "the image %s never arrived" % missing for reason in lost.values())
    wanted_elsewhere = {p for p in pairs if missing not in p}
    assert wanted_elsewhere <= set(project.matched())
    model = read_model(report["model_path"]).image_by_name()
    assert sorted(model) == sorted(k.name for k in corrected if k.name != missing)
    assert np.allclose(centre_of(model[jumped].qvec, model[jumped].tvec), corrected[10].position, atol=1e-6)
    for k in half:  # the model holds the corrected poses
        assert np.allclose(centre_of(model[k.name].qvec, model[k.name].tvec), np.asarray(k.position) + SHIFT,
                           atol=1e-6)
    assert report["points"] > 200
    json.dumps(report, default=str)  # what report.json is made of


def test_a_pair_whose_images_share_nothing_is_not_handed_to_colmaps_matcher(tmp_path):
    """A keyframe whose image shows nothing of its neighbour's (a noise texture where the walk
    was): neither the poses nor the images guide its pair, and fewer than 15 of its features pass
    COLMAP's matching tests, so COLMAP's matcher is not started for it. It is stored as COLMAP
    stores a pair it cannot verify (its matches, a two-view geometry of no inliers, DEGENERATE),
    and COLMAP's own matches_importer, run on the same pair, does not verify it either."""
    import cv2
    import sqlite3
    from view_selection.colmap import database as cdb

    _, selection = walk_selection(tmp_path, 12)
    export = ExportFolder(str(selection))
    a, b = export.keyframes[:2]
    project = ColmapProject(str(tmp_path / "project"), threads=2)
    os.makedirs(project.images)
    shutil.copyfile(os.path.join(export.image_root(), a.name), os.path.join(project.images, a.name))
    os.makedirs(os.path.dirname(os.path.join(project.images, b.name)), exist_ok=True)
    noise = np.random.default_rng(3).integers(0, 256, (b.height // 8, b.width // 8), np.uint8)
    cv2.imwrite(os.path.join(project.images, b.name), cv2.resize(noise, (b.width, b.height)))
    project.open()
    backend = PoseGuidedBackend(project)
    work = LiveWork(project, backend=backend)
    work.extract([a, b])
    work.match_all([a, b], [(a.name, b.name)])
    totals = backend.path_totals()
    assert (totals["unmatched"], totals["fallback"], totals["fallback_runs"]) == (1, 0, 0), totals
    assert "pass COLMAP's tests" in backend.path_counts()["unmatched_pairs"]["%s %s" % (a.name, b.name)]
    ids = project.image_ids()
    with cdb.open_database(project.database) as d:
        stored = d.two_view_geometry(ids[a.name], ids[b.name])
        raw = d.matches(ids[a.name], ids[b.name])
    assert (stored["rows"], stored["config"]) == (0, cdb.DEGENERATE)
    assert len(raw) < 15
    assert (a.name, b.name) in project.matched() and project.verified_count() == 0

    # COLMAP's matcher on the same pair, in a copy of the project without it.
    other = ColmapProject(str(tmp_path / "colmap"), threads=2, image_dir=project.images)
    os.makedirs(other.root)
    shutil.copyfile(project.database, other.database)
    con = sqlite3.connect(other.database)
    con.execute("DELETE FROM matches")
    con.execute("DELETE FROM two_view_geometries")
    con.commit()
    con.close()
    other.open()
    assert other.match([(a.name, b.name)]) == 1
    with cdb.open_database(other.database) as d:
        assert d.two_view_geometry(ids[a.name], ids[b.name])["rows"] < 15
