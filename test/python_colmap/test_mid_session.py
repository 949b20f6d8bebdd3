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
