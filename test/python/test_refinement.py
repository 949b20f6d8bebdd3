"""The refinement's Python side (issue 29): the seeded drift, refine_model run as a process on a
model folder, and what happens to the model when the refinement cannot run."""
import json
import math
import os
import stat
import time

import numpy as np
import pytest

from view_selection import geometry
from view_selection.colmap import model as cm
from view_selection.evaluation.trajectory import ate_rmse
from view_selection.refinement import drift, refiner


def refine_tool():
    tools = os.environ.get("VIEW_SELECTION_TOOLS_DIR")
    if tools and os.path.isfile(os.path.join(tools, "refine_model")):
        return os.path.join(tools, "refine_model")
    try:
        return refiner.find_refine_tool()
    except refiner.RefinementError:
        pytest.skip("refine_model is not built (VIEW_SELECTION_TOOLS_DIR)")


def arc_poses(n=30):
    """Cameras on a 100-degree arc, 3 m from the origin, looking at it (centre, c2w quaternion)."""
    poses = []
    for i in range(n):
        a = math.radians(-50 + 100.0 * i / (n - 1))
        eye = np.array([3 * math.sin(a), -1.0, -3 * math.cos(a)])
        z = -eye / np.linalg.norm(eye)
        x = np.cross([0, 1, 0], z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        poses.append((tuple(eye), geometry.quaternion_of(np.stack([x, y, z], axis=1))))
    return poses


def known_pose_model(exact, given, rng, k=(525.0, 525.0, 319.5, 239.5), database=None, points=500):
    """Observations of `points` points at the exact poses (0.5 px noise), points triangulated at
    the `given` poses, observations beyond 4 px of them dropped: point_triangulator's model. With
    `database` (a path), also the project's database: images, keypoints, and every pair of a
    point's observations as verified matches."""
    points = rng.uniform(-1, 1, size=(points, 3))
    m = cm.Model({1: cm.Camera(1, "PINHOLE", 640, 480, k)})
    obs = {i: [] for i in range(len(exact))}
    w2c = [geometry.world_to_camera(c, q) for c, q in given]
    for i, (c, q) in enumerate(exact):
        r = geometry.rotation_of(q).T
        cam = (r @ (points - np.asarray(c)).T).T
        px = np.stack([k[0] * cam[:, 0] / cam[:, 2] + k[2], k[1] * cam[:, 1] / cam[:, 2] + k[3]], axis=1)
        px += rng.normal(scale=0.5, size=px.shape)
        ok = (cam[:, 2] > 0) & (px[:, 0] >= 0) & (px[:, 0] < 640) & (px[:, 1] >= 0) & (px[:, 1] < 480)
        obs[i] = [(p, px[p]) for p in np.nonzero(ok)[0]]
    xys = {i: [] for i in obs}
    ids = {i: [] for i in obs}
    tracks = {}
    for i, lst in obs.items():
        for p, xy in lst:
            tracks.setdefault(p, []).append((i, len(xys[i])))
            xys[i].append(xy)
            ids[i].append(-1)
    for p, track in tracks.items():
        if len(track) < 2:
            continue
        a = np.zeros((4, 4))
        for i, idx in track:
            q, t = w2c[i]
            proj = np.hstack([geometry.rotation_of(q), np.asarray(t).reshape(3, 1)])
            u = (xys[i][idx][0] - k[2]) / k[0]
            v = (xys[i][idx][1] - k[3]) / k[1]
            for row in (u * proj[2] - proj[0], v * proj[2] - proj[1]):
                a += np.outer(row, row)
        h = np.linalg.eigh(a)[1][:, 0]
        x = h[:3] / h[3]
        keep = []
        for i, idx in track:
            q, t = w2c[i]
            c = geometry.rotation_of(q) @ x + np.asarray(t)
            px = np.array([k[0] * c[0] / c[2] + k[2], k[1] * c[1] / c[2] + k[3]])
            if c[2] > 0 and np.linalg.norm(px - xys[i][idx]) <= 4.0:
                keep.append((i, idx))
        if len(keep) < 2:
            continue
        pid = int(p) + 1
        m.points[pid] = cm.Point3D(pid, x, (0, 0, 0), 0.5, [i + 1 for i, _ in keep], [idx for _, idx in keep])
        for i, idx in keep:
            ids[i][idx] = pid
    for i, (q, t) in enumerate(w2c):
        m.images[i + 1] = cm.Image(i + 1, q, t, 1, "image_%02d.png" % i, xys[i], ids[i])
    if database:
        from view_selection.colmap import database as cdb
        with cdb.open_database(database, create=True) as d:
            cid = d.camera_id(640, 480, k)
            for i in range(len(exact)):
                assert d.add_image("image_%02d.png" % i, cid) == i + 1
                d.write_features(i + 1, np.asarray(xys[i], np.float32).reshape(-1, 2),
                                 np.zeros((len(xys[i]), 128), np.uint8))
            pairs = {}
            for track in tracks.values():
                for x in range(len(track)):
                    for y in range(x + 1, len(track)):
                        (a, ia), (b, ib) = track[x], track[y]
                        pairs.setdefault((a + 1, b + 1), []).append((ia, ib))
            for (a, b), matches in pairs.items():
                d.write_matches(a, b, matches)
                # the pair's relative pose as its matches give it: the exact one
                ra, rb = (geometry.rotation_of(q).T for _, q in (exact[a - 1], exact[b - 1]))
                r = rb @ ra.T
                t = -rb @ np.asarray(exact[b - 1][0]) + r @ ra @ np.asarray(exact[a - 1][0])
                d.write_two_view_geometry(a, b, matches, qvec=geometry.quaternion_of(r), tvec=tuple(t))
    return m


def centres(model):
    return [geometry.centre_of(im.qvec, im.tvec) for _, im in sorted(model.images.items())]


def test_drift_is_seeded_starts_exact_and_grows():
    exact = arc_poses(40)
    a = drift.add_drift(exact, 0.02, 0.3, seed=7)
    b = drift.add_drift(exact, 0.02, 0.3, seed=7)
    c = drift.add_drift(exact, 0.02, 0.3, seed=8)
    assert a == b and a != c
    assert np.allclose(a[0][0], exact[0][0]) and np.allclose(a[0][1], exact[0][1])
    errors = [np.linalg.norm(np.subtract(d[0], e[0])) for d, e in zip(a, exact)]
    assert np.mean(errors[-10:]) > np.mean(errors[1:11])  # a random walk: the end is further off
    turned = geometry.rotation_angle_deg(a[-1][1], exact[-1][1])
    assert 0.3 < turned < 0.3 * 39 + 1e-9
    assert drift.add_drift(exact, 0.0, 0.0) == [(tuple(map(float, c)), geometry.quaternion_of(geometry.rotation_of(q)))
                                                for c, q in exact]


def test_drifted_tum_folder_keeps_the_exact_poses_beside(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    rows = [(1000.0 + i, c, q) for i, (c, q) in enumerate(arc_poses(10))]
    drift.write_groundtruth(str(src / "groundtruth.txt"), rows)
    (src / "rgb.txt").write_text("# rgb\n")
    exact, drifted = drift.drifted_tum_folder(str(src), str(tmp_path / "out"), seed=1)
    assert os.path.islink(tmp_path / "out" / "rgb.txt")
    back = drift.read_groundtruth(str(tmp_path / "out" / "groundtruth_exact.txt"))
    assert [s for s, _, _ in back] == [s for s, _, _ in rows]
    assert np.allclose([c for _, c, _ in back], [c for _, c, _ in rows], atol=1e-8)
    assert drift.read_groundtruth(str(tmp_path / "out" / "groundtruth.txt"))[5][1] != back[5][1]


def test_refine_brings_a_drifted_model_closer(tmp_path):
    tool = refine_tool()
    rng = np.random.default_rng(29)
    exact = arc_poses()
    given = drift.add_drift(exact, 0.02, 0.3, seed=3)
    m = known_pose_model(exact, given, rng, database=str(tmp_path / "database.db"))
    cm.write_model(m, str(tmp_path / "in"))
    section = refiner.refine(str(tmp_path / "in"), str(tmp_path / "out"), tool=tool,
                             database=str(tmp_path / "database.db"))
    out = cm.read_model(str(tmp_path / "out"))
    truth = [c for c, _ in exact]
    before, after = ate_rmse(centres(m), truth), ate_rmse(centres(out), truth)
    assert after < 0.5 * before, (before, after, section["message"])
    assert section["refined"] and section["status"] == "converged"
    assert section["retriangulations"] == 2 and section["matches"] > 1000  # the database's matches reached it
    assert len(section["keyframes"]) == 30 and section["keyframes_refined"] == 30
    by_name = {k["name"]: k for k in section["keyframes"]}
    moved = refiner.corrections(m, out)
    for name, (t, r) in moved.items():
        assert by_name[name]["translation"] == pytest.approx(t, abs=1e-9)
        assert by_name[name]["rotation_deg"] == pytest.approx(r, abs=1e-6)
    assert section["translation_max"] >= section["translation_median"] > 0
    assert section["reprojection_error"][1] < section["reprojection_error"][0]
    # The finish's statistics come from the report, not from reading the model back: the same.
    stats, read = section["statistics"], out.statistics()
    assert {k: stats[k] for k in ("registered", "points", "observations")} == \
        {k: read[k] for k in ("registered", "points", "observations")}
    for k in ("track_length", "obs_per_image", "reprojection_error"):
        assert stats[k] == pytest.approx(read[k], rel=1e-6), k
    assert section["phase_seconds"]["adjustment"] > 0 and section["phase_seconds"]["reading"] > 0
    assert not os.listdir(tmp_path / "out") == []
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".refine_")]  # its work folder is gone


def test_a_time_budget_gives_what_the_adjustment_reached(tmp_path):
    """The bridge's finish gives the refinement a budget (~refine_max_seconds): far below what
    this model's refinement takes, it stops out of time, sooner, and still brings it closer."""
    tool = refine_tool()
    exact = arc_poses()
    given = drift.add_drift(exact, 0.02, 0.3, seed=3)
    m = known_pose_model(exact, given, np.random.default_rng(29), database=str(tmp_path / "database.db"))
    cm.write_model(m, str(tmp_path / "in"))
    full = refiner.refine(str(tmp_path / "in"), str(tmp_path / "full"), tool=tool, database=str(tmp_path / "database.db"))
    # The budget covers the whole refinement (the matches file and refine_model's reading too):
    # too small a share of it leaves no time for one adjustment after the epipolar stage and the
    # triangulation (the model as it came, or the epipolar stage's poses with their points);
    # how much that is depends on the machine's load, so a few shares are tried, from a third
    # of the full run's time, until one is cut short with an adjustment made.
    assert full["status"] == "converged"
    for share in (0.35, 0.45, 0.55, 0.65, 0.75):
        cut = refiner.refine(str(tmp_path / "in"), str(tmp_path / "out"),
                             refiner.RefinementOptions(max_seconds=share * full["seconds"]),
                             tool=tool, database=str(tmp_path / "database.db"))
        if cut["refined"] and cut["status"] == "out_of_time" and cut["rounds"] > 0:
            break  # an adjustment began (with none, the epipolar stage's poses may stand alone)
    assert cut["status"] == "out_of_time", cut["message"]
    assert cut["refined"] and "time budget" in cut["message"]
    # Cut short: less adjustment time than the full run's. Its rounds may equal the full run's
    # (a budget that runs out in the last round still counts that round: seen once under load,
    # "2 < 2"), never more.
    assert cut["rounds"] <= full["rounds"] and cut["adjustment_seconds"] < full["adjustment_seconds"]
    truth = [c for c, _ in exact]
    assert ate_rmse(centres(cm.read_model(str(tmp_path / "out"))), truth) < ate_rmse(centres(m), truth)


def test_a_model_returned_as_it_came_is_linked_not_written_again(tmp_path):
    """A refinement that returns its input (a budget spent on reading: a 30-minute session's
    finish) gives the input's files as the output, hard-linked, not written again; one that
    refined writes its own."""
    tool = refine_tool()
    exact = arc_poses()
    m = known_pose_model(exact, drift.add_drift(exact, 0.02, 0.3, seed=3), np.random.default_rng(5))
    cm.write_model(m, str(tmp_path / "in"))
    spent = refiner.run_refine_model(tool, str(tmp_path / "in"), str(tmp_path / "spent"), str(tmp_path / "spent.json"),
                                     refiner.RefinementOptions(max_seconds=1e-6))
    assert spent["unchanged"] and not spent["refined"], spent["message"]
    refined = refiner.run_refine_model(tool, str(tmp_path / "in"), str(tmp_path / "refined"),
                                       str(tmp_path / "refined.json"), refiner.RefinementOptions())
    assert refined["refined"] and not refined["unchanged"], refined["message"]
    for name in ("cameras.bin", "images.bin", "points3D.bin"):
        given = os.stat(str(tmp_path / "in" / name))
        assert os.stat(str(tmp_path / "spent" / name)).st_ino == given.st_ino, name
        assert os.stat(str(tmp_path / "refined" / name)).st_ino != given.st_ino, name
    same_model = cm.read_model(str(tmp_path / "spent"))
    assert sorted(same_model.images) == sorted(m.images) and len(same_model.points) == len(m.points)


def fake_tool(path, body):
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return str(path)


class FakeProject:
    def __init__(self, root):
        self.log_path = os.path.join(root, "colmap.log")
        self.database = None
        self.deadline = None


def test_a_failing_refinement_leaves_the_unrefined_model(tmp_path):
    model = tmp_path / "sparse" / "0"
    m = known_pose_model(arc_poses(5), arc_poses(5), np.random.default_rng(1))
    cm.write_model(m, str(model))
    before = {n: open(os.path.join(model, n), "rb").read() for n in os.listdir(model)}
    tool = fake_tool(tmp_path / "refine_model", "echo 'refine_model: error: it broke' >&2; exit 1")
    logged = []
    section = refiner.ModelRefinement(tool=tool, log=lambda level, text: logged.append((level, text))).apply(
        FakeProject(str(tmp_path)), str(model))
    assert section["refined"] is False and section["status"] == "error"
    assert "it broke" in section["error"] and logged and logged[0][0] == "error"
    assert {n: open(os.path.join(model, n), "rb").read() for n in os.listdir(model)} == before
    assert sorted(os.listdir(tmp_path / "sparse" / "unrefined")) == sorted(before)


def test_a_model_its_budget_cannot_refine_is_said_once_and_kept_as_written(tmp_path):
    """The bridge's finish on a session too long for ~refine_max_seconds (30 minutes): one
    warning that says the model is not refined and what would refine it (not a keyframe's
    "kept"), and sparse/0 stays the files written, linked back, not written again."""
    model = tmp_path / "sparse" / "0"
    exact = arc_poses()
    cm.write_model(known_pose_model(exact, drift.add_drift(exact, 0.02, 0.3, seed=3), np.random.default_rng(2)),
                   str(model))
    inodes = {n: os.stat(str(model / n)).st_ino for n in os.listdir(str(model))}
    logged = []
    section = refiner.ModelRefinement(refiner.RefinementOptions(max_seconds=1e-6), tool=refine_tool(),
                                      log=lambda level, text: logged.append((level, text))).apply(
        FakeProject(str(tmp_path)), str(model))
    assert section["status"] == "out_of_time" and not section["refined"], section["message"]
    warnings = [text for level, text in logged if level == "warn"]
    assert len(warnings) == 1 and "not refined" in warnings[0] and "~refine_max_seconds" in warnings[0], logged
    assert {n: os.stat(str(model / n)).st_ino for n in os.listdir(str(model))} == inodes


def test_a_finish_from_earlier_poses_starts_there_and_measures_against_the_given_ones(tmp_path):
    """ModelRefinement.apply with start_poses (the poses refined while the recording went on,
    refinement/background.py): refine_model --start. Out of time, sparse/0 is the model at the
    start poses, its points carried by their first image; sparse/unrefined stays at the given
    poses. With time, the corrections are measured against the given poses, the finish has no
    epipolar stage of its own, and the result is no worse than where it started."""
    exact = arc_poses()
    given = drift.add_drift(exact, 0.02, 0.3, seed=3)
    database = str(tmp_path / "database.db")
    m = known_pose_model(exact, given, np.random.default_rng(11), database=database)
    project = FakeProject(str(tmp_path))
    project.database = database
    half = drift.add_drift(exact, 0.01, 0.15, seed=3)  # "the runs' poses": half the drift
    start = {iid: geometry.world_to_camera(*half[iid - 1]) for iid in m.images}
    truth = [c for c, _ in exact]
    for budget, folder in ((1e-6, "cut"), (0.0, "full")):
        model = tmp_path / folder / "sparse" / "0"
        cm.write_model(m, str(model))
        section = refiner.ModelRefinement(refiner.RefinementOptions(max_seconds=budget), tool=refine_tool()).apply(
            project, str(model), start_poses=start)
        assert "started_from" in section, section
        out = cm.read_model(str(model))
        unrefined = cm.read_model(str(tmp_path / folder / "sparse" / "unrefined"))
        assert np.allclose(centres(unrefined), centres(m), atol=1e-9)
        if folder == "cut":
            assert section["status"] == "out_of_time" and not section["refined"], section["message"]
            assert np.allclose(centres(out), [c for c, _ in half], atol=1e-6)
            for pid, p in list(m.points.items())[:50]:  # in its first image, a point stays where it was
                first = p.image_ids[0]
                was = geometry.rotation_of(m.images[first].qvec) @ p.xyz + np.asarray(m.images[first].tvec)
                now = geometry.rotation_of(out.images[first].qvec) @ out.points[pid].xyz + \
                    np.asarray(out.images[first].tvec)
                assert np.allclose(was, now, atol=1e-6)
        else:
            assert section["refined"], section["message"]
            assert (section["epipolar"] or {}).get("iterations", 0) == 0, section["epipolar"]
            by_name = {k["name"]: k for k in section["keyframes"]}
            for name, (t, _) in refiner.corrections(m, out).items():
                assert by_name[name]["translation"] == pytest.approx(t, abs=1e-9)
            assert ate_rmse(centres(out), truth) < ate_rmse([c for c, _ in half], truth)
    assert not [n for n in os.listdir(tmp_path / "full" / "sparse") if n.startswith(".start_")]


def as_table(model):
    """The model with its points as a colmap.model.PointTable (as the live model hands them)."""
    ids = sorted(model.points)
    points = [model.points[i] for i in ids]
    counts = [len(p.image_ids) for p in points]
    table = cm.PointTable(ids, [p.xyz for p in points], [p.rgb for p in points], [p.error for p in points],
                          np.concatenate([[0], np.cumsum(counts)]),
                          np.concatenate([p.image_ids for p in points]), np.concatenate([p.point2D_idxs for p in points]))
    return cm.Model(dict(model.cameras), dict(model.images), table)


def test_a_finish_from_earlier_poses_its_budget_cannot_refine_makes_that_model_without_refine_model(tmp_path):
    """The finish from the runs' poses on a model its budget pays nothing for (30 minutes): given
    the live model, the model at the start poses is made here (refiner.carried), and is the one
    refine_model --start gives out of time: the same poses, points, reprojection errors and
    corrections against the given poses."""
    exact = arc_poses()
    database = str(tmp_path / "database.db")
    m = known_pose_model(exact, drift.add_drift(exact, 0.02, 0.3, seed=3), np.random.default_rng(11),
                         database=database)
    project = FakeProject(str(tmp_path))
    project.database = database
    half = drift.add_drift(exact, 0.01, 0.15, seed=3)
    start = {iid: geometry.world_to_camera(*half[iid - 1]) for iid in m.images}
    matched = refiner.count_matched_observations(database)
    budget = 0.5 * skipped_below(m, matched)
    out, sections, logged = {}, {}, []
    for folder, given in (("refine_model", None), ("here", as_table(m))):
        model = tmp_path / folder / "sparse" / "0"
        cm.write_model(m, str(model))
        sections[folder] = refiner.ModelRefinement(
            refiner.RefinementOptions(max_seconds=budget), tool=refine_tool(),
            log=lambda level, text: logged.append(text)).apply(project, str(model), model=given, matched=matched,
                                                                start_poses=start)
        out[folder] = cm.read_model(str(model))
        assert sections[folder]["status"] == "out_of_time" and not sections[folder]["refined"]
        assert "started_from" in sections[folder]
    assert "refine_model not started" in sections["here"]["message"], sections["here"]["message"]
    assert "refine_model not started" not in sections["refine_model"]["message"]
    assert np.allclose(centres(out["here"]), [c for c, _ in half], atol=1e-9)
    assert np.allclose(centres(out["here"]), centres(out["refine_model"]), atol=1e-9)
    a, b = out["here"].points, out["refine_model"].points
    assert len(a) == len(b) == len(m.points)
    for pid in m.points:
        assert np.allclose(a[pid].xyz, b[pid].xyz, atol=1e-7), pid
    # refine_model reports the error at the start poses (its points3D.bin keeps the input's)
    made = out["here"].statistics()["reprojection_error"]
    assert made == pytest.approx(sections["refine_model"]["reprojection_error"][1], rel=1e-6)
    assert sections["here"]["reprojection_error"] == [pytest.approx(made)] * 2
    assert made > 2.0 * m.statistics()["reprojection_error"]  # the drift left is seen
    ours = {k["name"]: k for k in sections["here"]["keyframes"]}
    for k in sections["refine_model"]["keyframes"]:
        assert ours[k["name"]]["translation"] == pytest.approx(k["translation"], abs=1e-7)
        assert ours[k["name"]]["rotation_deg"] == pytest.approx(k["rotation_deg"], abs=1e-6)
    assert not [n for n in os.listdir(tmp_path / "here" / "sparse") if n.startswith(".start_")]


def test_the_runs_matches_kept_between_runs_are_the_file_write_matches_writes(tmp_path):
    """refiner.SampledMatches (the runs while the recording goes on): written again as the
    database changes (a pair verified anew with other inliers, a pair that lost its geometry, a
    pair added), the file is write_matches(per_pair=...)'s byte for byte, and a pair whose inliers
    did not change is not read again."""
    from view_selection.colmap import database as cdb
    exact = arc_poses()
    database = str(tmp_path / "database.db")
    known_pose_model(exact, drift.add_drift(exact, 0.02, 0.3, seed=3), np.random.default_rng(5), database=database)
    sampled = refiner.SampledMatches(8)
    added = (29, 30)  # verified only later
    with cdb.open_database(database) as d:
        d.con.execute("DELETE FROM two_view_geometries WHERE pair_id = ?", (cdb.pair_id(*added),))

    def same():
        sampled.write(database, str(tmp_path / "kept.bin"))
        refiner.write_matches(database, str(tmp_path / "read.bin"), per_pair=8)
        return open(str(tmp_path / "kept.bin"), "rb").read() == open(str(tmp_path / "read.bin"), "rb").read()
    assert same()
    with cdb.open_database(database) as d:
        pairs = sorted(p for p, n in d.inlier_counts().items() if n > 10)
        (a, b), (c, e) = pairs[0], pairs[1]
        d.write_two_view_geometry(a, b, d.matches(a, b, "two_view_geometries")[::2])  # matched again
        d.con.execute("DELETE FROM two_view_geometries WHERE pair_id = ?", (cdb.pair_id(c, e),))
        d.write_two_view_geometry(*added, np.stack([np.arange(20), np.arange(20)], axis=1))
    unchanged = pairs[2]
    kept = {p: rows for p, (_, rows) in sampled.pairs.items()}
    assert added not in kept
    assert same()
    assert (c, e) not in sampled.pairs and added in sampled.pairs
    assert sampled.pairs[(a, b)][1] is not kept[(a, b)]
    assert sampled.pairs[unchanged][1] is kept[unchanged]  # not read again


def test_the_pairs_rotations_are_those_estimated_from_their_matches(tmp_path):
    """refiner.write_rotations: each verified pair's relative rotation (the second image's
    world-to-camera rotation relative to the first's), as many inliers as the epipolar stage
    takes a pair with; a geometry COLMAP estimated no pose for (zero qvec and tvec) and a pair
    with fewer inliers are left out; `pairs` gives only those."""
    import struct
    from view_selection.colmap import database as cdb
    exact = arc_poses(6)
    database = str(tmp_path / "database.db")
    known_pose_model(exact, exact, np.random.default_rng(5), database=database)
    with cdb.open_database(database) as d:
        d.write_two_view_geometry(1, 2, d.matches(1, 2, "two_view_geometries"), qvec=(0, 0, 0, 0))  # "none"
        d.write_two_view_geometry(2, 3, d.matches(2, 3, "two_view_geometries")[:refiner.ROTATION_MIN_INLIERS - 1],
                                  qvec=(1, 0, 0, 0), tvec=(1, 0, 0))
        # given in the other order: stored as (3, 5), the rotation inverted
        q35 = d.two_view_geometry(3, 5)["qvec"]
        d.write_two_view_geometry(5, 3, d.matches(3, 5, "two_view_geometries")[:, ::-1],
                                  qvec=geometry.quaternion_of(geometry.rotation_of(q35).T), tvec=(0, 0, 1))
        verified = sorted(p for p, n in d.inlier_counts().items() if n >= refiner.ROTATION_MIN_INLIERS)
    path = str(tmp_path / "rotations.bin")
    n = refiner.write_rotations(database, path)
    data = open(path, "rb").read()
    assert data[:8] == b"VSROTAT1" and struct.unpack("<Q", data[8:16])[0] == n == len(verified) - 1
    rows = [struct.unpack("<ii4d", data[16 + 40 * k:56 + 40 * k]) for k in range(n)]
    assert sorted((a, b) for a, b, *_ in rows) == [p for p in verified if p != (1, 2)]
    for a, b, *q in rows:
        ra, rb = (geometry.rotation_of(exact[i - 1][1]).T for i in (a, b))
        assert geometry.rotation_angle_deg(q, geometry.quaternion_of(rb @ ra.T)) < 1e-6, (a, b)
    assert refiner.write_rotations(database, path, pairs=[(5, 3), (1, 2)]) == 1


def test_refine_gives_refine_model_the_pairs_rotations(tmp_path):
    """refiner.refine gives refine_model the database's pair rotations: a model whose heading
    drifted 4 degrees a step (116 over the arc) starts from the averaged rotations (the report
    says so; refine_model --no-rotations, through VS_REFINE_EXTRA, the development switch, does
    not), and ends where the full refinement ends without them: on the arc every image sees
    every other, and the adjustment corrects it either way (what the start changes on a long
    walk is measured in docs/design.md; test_rotation_averaging and test_model_refinement hold
    the stage to it)."""
    exact = arc_poses()
    given = []
    turn = np.eye(3)
    centre = np.asarray(exact[0][0])
    for i, (c, q) in enumerate(exact):
        if i:
            step = np.asarray(c) - np.asarray(exact[i - 1][0])
            a = math.radians(4.0)
            turn = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]]) @ turn
            centre = centre + turn @ step
        given.append((tuple(centre), geometry.quaternion_of(turn @ geometry.rotation_of(q))))
    database = str(tmp_path / "database.db")
    model = known_pose_model(exact, given, np.random.default_rng(8), database=database)
    cm.write_model(model, str(tmp_path / "in"))
    options = refiner.RefinementOptions(threads=1)
    options.max_correction_deg = 180.0  # 116 degrees over the arc's 5 m: beyond the plausibility check
    options.max_correction_depth_ratio = 100.0
    out = {}
    for name, extra in (("with", ""), ("without", "--no-rotations")):
        os.environ["VS_REFINE_EXTRA"] = extra
        try:
            out[name] = refiner.refine(str(tmp_path / "in"), str(tmp_path / name), options, database=database,
                                       tool=refine_tool())
        finally:
            del os.environ["VS_REFINE_EXTRA"]
    assert out["with"]["epipolar"]["rotation_pairs"] == 435
    assert out["with"]["epipolar"]["rotations_adopted"] is True
    assert out["without"]["epipolar"]["rotations_adopted"] is False
    truth = [c for c, _ in exact]
    errors = {name: ate_rmse(centres(cm.read_model(str(tmp_path / name))), truth) for name in out}
    assert errors["with"] < 0.005 and errors["with"] < 1.05 * errors["without"], errors


def skipped_below(model, matched, matches=0):
    """The budget under which the finish does not start refine_model (refiner.not_begun)."""
    return refiner.READING_SECONDS_PER_MATCH * matches + \
        min(2.0 * refiner.TRIANGULATION_SECONDS_PER_OBSERVATION * matched,
            refiner.ADJUSTMENT_ALONE_SECONDS_PER_OBSERVATION * model.statistics()["observations"])


def test_refine_model_begins_nothing_where_the_finish_does_not_start_it(tmp_path):
    """refiner.not_begun's rule against refine_model itself: with a budget just under it (less the
    reading's credit, below), refine_model given the matches begins nothing (no tracks, no round, every image kept); with
    ten times it, it begins. A refine_model whose steps grew cheaper than the constants say (the
    finish would skip what it could do) breaks the first; constants far above its rule, the
    second."""
    exact = arc_poses()
    database = str(tmp_path / "database.db")
    m = known_pose_model(exact, drift.add_drift(exact, 0.02, 0.3, seed=3), np.random.default_rng(5),
                         database=database, points=3000)
    cm.write_model(m, str(tmp_path / "in"))
    matches = str(tmp_path / "matches.bin")
    count = refiner.write_matches(database, matches)
    matched = refiner.count_matched_observations(database)
    assert matched >= m.statistics()["observations"]
    bound = 0.99 * skipped_below(m, matched, count)  # its reading of the matches counted in
    assert refiner.not_begun(m, matched, refiner.RefinementOptions(max_seconds=bound), bound, count) is not None
    assert refiner.not_begun(m, matched, refiner.RefinementOptions(max_seconds=10 * bound), 10 * bound, count) is None
    # refine_model spends its own reading time out of the budget, and a fast machine reads faster
    # than READING_SECONDS_PER_MATCH (0.022 us a match here, hot cache): given the reading's credit
    # it began the triangulation's gate with time to spare, gave the triangulation up after its
    # setup, and adjusted. So the run just under the rule gets no credit for reading: whatever the
    # machine reads at, what is left is under the steps' own constants.
    reports = {}
    for factor, budget in ((1.0, 0.99 * skipped_below(m, matched)), (10.0, 10 * bound)):
        options = refiner.RefinementOptions(max_seconds=budget, threads=1)
        reports[factor] = refiner.run_refine_model(refine_tool(), str(tmp_path / "in"), str(tmp_path / str(factor)),
                                                   str(tmp_path / ("%s.json" % factor)), options, matches=matches)
    r = reports[1.0]
    assert r["status"] == "out_of_time" and not r["refined"], r["message"]
    assert (r["tracks"], r["rounds"], r["iterations"], r["retriangulations"]) == (0, 0, 0, 0), r["message"]
    assert all(im["kept"] for im in r["images"])
    r = reports[10.0]
    assert r["tracks"] > 0 and r["rounds"] > 0, r["message"]


def test_a_finish_whose_budget_pays_for_nothing_does_not_start_refine_model(tmp_path):
    """ModelRefinement.apply given the model it refines and its matches' observations (the live
    finish): under not_begun's rule refine_model is not started, and the section is the one
    refine_model gives for a budget that pays for nothing, with the same fields; sparse/0 stays
    as written and sparse/unrefined is its copy. Over it, or without the model, it is started."""
    exact = arc_poses()
    database = str(tmp_path / "database.db")
    m = known_pose_model(exact, drift.add_drift(exact, 0.02, 0.3, seed=3), np.random.default_rng(2),
                         database=database)
    model = tmp_path / "sparse" / "0"
    cm.write_model(m, str(model))
    before = {n: open(os.path.join(model, n), "rb").read() for n in os.listdir(model)}
    project = FakeProject(str(tmp_path))
    project.database = database
    started = tmp_path / "started"
    tool = fake_tool(tmp_path / "refine_model", "touch %s; exit 1" % started)
    matched = refiner.count_matched_observations(database)
    bound = skipped_below(m, matched)
    logged = []
    section = refiner.ModelRefinement(refiner.RefinementOptions(max_seconds=0.5 * bound), tool=tool,
                                      log=lambda level, text: logged.append((level, text))).apply(
        project, str(model), m, matched)
    assert not started.exists()
    assert section["status"] == "out_of_time" and not section["refined"], section
    assert "not started" in section["message"] and section["not_begun"] == ["epipolar", "triangulation", "adjustment"]
    assert [k["name"] for k in section["keyframes"]] == [im.name for _, im in sorted(m.images.items())]
    assert all(k["kept"] and not k["refined"] for k in section["keyframes"])
    assert [k["observations"][0] for k in section["keyframes"]] == \
        [int(np.count_nonzero(np.asarray(im.point3D_ids) >= 0)) for _, im in sorted(m.images.items())]
    assert section["statistics"] == m.statistics()
    warnings = [text for level, text in logged if level == "warn"]
    assert len(warnings) == 1 and "not refined" in warnings[0], logged
    assert {n: open(os.path.join(model, n), "rb").read() for n in os.listdir(model)} == before
    assert {n: open(os.path.join(tmp_path / "sparse" / "unrefined", n), "rb").read()
            for n in os.listdir(tmp_path / "sparse" / "unrefined")} == before
    # refine_model's own section for a budget that pays for nothing has the same fields.
    real = refiner.ModelRefinement(refiner.RefinementOptions(max_seconds=1e-6), tool=refine_tool()).apply(
        project, str(model))
    assert real["status"] == "out_of_time" and not real["refined"]
    assert sorted(section) == sorted(real)
    # Well over the rule (what writing the matches takes comes out of it), or without the model or
    # its matches, refine_model is started.
    for budget, given, count in ((100 * bound, m, matched), (0.5 * bound, None, matched), (0.5 * bound, m, 0)):
        started.unlink(missing_ok=True)
        section = refiner.ModelRefinement(refiner.RefinementOptions(max_seconds=budget), tool=tool).apply(
            project, str(model), given, count)
        assert started.exists() and section["status"] == "error", (budget, given, count)


def test_a_hung_refinement_is_killed_at_its_timeout(tmp_path):
    m = known_pose_model(arc_poses(5), arc_poses(5), np.random.default_rng(1))
    cm.write_model(m, str(tmp_path / "in"))
    tool = fake_tool(tmp_path / "refine_model", "sleep 60")
    start = time.monotonic()
    with pytest.raises(refiner.RefinementError, match="did not finish within"):
        refiner.refine(str(tmp_path / "in"), str(tmp_path / "out"), refiner.RefinementOptions(timeout=2), tool=tool)
    assert time.monotonic() - start < 20
    assert not os.path.exists(tmp_path / "out")


def test_options_reach_the_tool(tmp_path):
    args, fixed = tmp_path / "args.txt", tmp_path / "fixed.txt"
    tool = fake_tool(tmp_path / "refine_model", 'echo "$@" > %s; while [ $# -gt 0 ]; do [ "$1" = --fixed ] && '
                     'cat "$2" > %s; shift; done; exit 3' % (args, fixed))
    with pytest.raises(refiner.RefinementError, match="exit 3"):
        refiner.refine(str(tmp_path), str(tmp_path / "out"),
                       refiner.RefinementOptions(loss="huber", max_correction_deg=7.5, max_seconds=4.5),
                       fixed=["a.png"], tool=tool)
    text = args.read_text()
    assert "--loss huber" in text and "--max-correction-deg 7.5" in text and "--fixed" in text
    # What is left of the budget: the time since refine() began (no matches to write here) is
    # taken off, a few milliseconds at most.
    budget = float(text.split("--max-seconds ")[1].split()[0])
    assert 4.0 < budget < 4.5
    assert fixed.read_text() == "a.png\n"
    json.dumps(refiner.RefinementOptions().to_json())  # goes into report.json


def test_progress_lines_are_relayed_as_they_come_and_a_hang_is_still_killed(tmp_path):
    # refine_model's progress on stderr reaches the caller line by line (colmap_from_selection
    # shows them), asked for a line a second; its stderr still makes the error.
    args = tmp_path / "args.txt"
    tool = fake_tool(tmp_path / "refine_model", 'echo "$@" > %s; echo "adjusting 1/4 rounds" >&2; '
                     'echo "adjusting 2/4 rounds" >&2; echo "refine_model: error: it broke" >&2; exit 3' % args)
    lines = []
    with pytest.raises(refiner.RefinementError, match="(?s)exit 3.*it broke"):
        refiner.refine(str(tmp_path), str(tmp_path / "out"), tool=tool, progress=lines.append)
    assert lines == ["adjusting 1/4 rounds", "adjusting 2/4 rounds", "refine_model: error: it broke"]
    assert "--progress-interval 1" in args.read_text()
    # A tool that prints and then hangs is killed at its timeout, as without progress.
    tool = fake_tool(tmp_path / "hangs", 'echo "adjusting 0/4 rounds" >&2; sleep 60')
    lines, start = [], time.monotonic()
    with pytest.raises(refiner.RefinementError, match="did not finish within"):
        refiner.refine(str(tmp_path), str(tmp_path / "out2"), refiner.RefinementOptions(timeout=2), tool=tool,
                       progress=lines.append)
    assert time.monotonic() - start < 20
    assert lines == ["adjusting 0/4 rounds"]
