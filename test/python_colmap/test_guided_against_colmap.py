"""Pose-guided matching against COLMAP's own extraction and matching, on the same keyframes and
pairs of the shared kitchen (issue 28): guided matching finds at least 90% of COLMAP's verified
inlier matches over the pairs both verify, and every guided inlier lies within its pair's band of
the poses' epipolar lines. What the guided matcher stores as verified is what COLMAP's own
verification would accept (issue 35): read back from the database's blobs with COLMAP's
conventions, every inlier lies within COLMAP's threshold of the stored geometry, and COLMAP's
point_triangulator reads the database."""
import json
import os
import sqlite3
import subprocess

import numpy as np
import pytest

from conftest import DATA, colmap_from_selection, run, tool, without_real_data
from view_selection.colmap.database import Database
from view_selection.export_folder import ExportFolder
from view_selection.features.sift import Features
from view_selection.matching import guided

KITCHEN = os.path.join(DATA, "redkitchen-0-499")


def inliers_by_pair(database):
    with Database(database) as d:
        names = {i: n for n, i in d.image_ids().items()}
        return {tuple(sorted((names[a], names[b]))): n for (a, b), n in d.inlier_counts().items()}


@pytest.fixture(scope="module")
def kitchen(tmp_path_factory):
    """The kitchen's selection and the guided project on it at the given poses (--refine off:
    issue 29's refinement would move them), shared by the tests of this file."""
    if not os.path.isdir(KITCHEN):
        without_real_data("test_guided_against_colmap", KITCHEN)
    tmp = tmp_path_factory.mktemp("kitchen")
    run([tool("select_views"), "--dataset", KITCHEN, "--out", str(tmp / "selection"), "--quiet", "--print-sets", "0"])
    colmap_from_selection(tmp / "selection", "--model", "known_poses", "--matcher", "guided", "--out", tmp / "guided",
                          "--threads", "2", "--refine", "off")
    return tmp


def test_guided_finds_what_colmap_verifies_on_the_kitchen(kitchen):
    tmp_path, selection = kitchen, kitchen / "selection"
    # COLMAP's own pipeline on the same pairs: its extraction, matches_importer, point_triangulator
    colmap_from_selection(selection, "--model", "known_poses", "--matcher", "colmap", "--triangulation", "colmap",
                          "--out", tmp_path / "colmap", "--threads", "2", "--refine", "off")
    g = inliers_by_pair(str(tmp_path / "guided" / "database.db"))
    c = inliers_by_pair(str(tmp_path / "colmap" / "database.db"))
    both = [p for p in c if c[p] > 0 and g.get(p, 0) > 0]
    assert len(both) >= 0.9 * len([p for p in c if c[p] > 0])
    share = sum(g[p] for p in both) / sum(c[p] for p in both)
    assert share >= 0.9, "guided inliers are %.2f of COLMAP's" % share

    # Every guided inlier within the band its pair reports, of the poses' epipolar lines.
    report = json.load(open(str(tmp_path / "guided" / "report.json")))
    paths = report["matching"]["pairs"]
    assert report["matching"]["guided"] > 0.8 * report["pairs_matched"]
    keyframes = {k.name: k for k in ExportFolder(str(selection)).keyframes}
    with Database(str(tmp_path / "guided" / "database.db")) as d:
        ids = d.image_ids()
        for key, summary in paths.items():
            if summary["path"] != guided.GUIDED:
                continue
            a, b = key.split()
            fa = Features.from_colmap(d.keypoints(ids[a]), d.descriptors(ids[a]))
            fb = Features.from_colmap(d.keypoints(ids[b]), d.descriptors(ids[b]))
            m = d.matches(ids[a], ids[b], "two_view_geometries")
            ka, kb = keyframes[a], keyframes[b]
            r, t = guided.relative_pose(ka, kb)
            f = guided.fundamental(guided.skew(t / np.linalg.norm(t)) @ r, guided.intrinsic_matrix(ka),
                                   guided.intrinsic_matrix(kb))
            distances = np.diag(guided.epipolar_distances(f, fa.xy[m[:, 0]], fb.xy[m[:, 1]]))
            assert np.all(distances <= summary["band_px"] + 1e-3), key

    # The known-pose model: at least as many points as COLMAP's pipeline makes, no higher error.
    gm, cm = json.load(open(str(tmp_path / "guided" / "report.json"))), json.load(open(str(tmp_path / "colmap" / "report.json")))
    assert gm["registered"] == cm["registered"] == len(keyframes)
    assert gm["points"] >= cm["points"]
    assert gm["reprojection_error"] <= cm["reprojection_error"]


# COLMAP 3.8's conventions, written out here (not the package's reader) so that the check does
# not share the writer's mistakes: pair_id = id1 * 2147483647 + id2 (id1 < id2); blobs
# row-major, matches uint32 (idx1 of id1, idx2 of id2), F and E float64 3x3 with x2^T F x1 = 0,
# keypoints float32 with the top-left pixel's centre at (0.5, 0.5); a PINHOLE camera's params
# fx, fy, cx, cy in the same convention. TwoViewGeometryOptions: RANSAC max_error 4 px on the
# squared Sampson error; E's threshold is max_error over the mean focal length, averaged over the
# two cameras (TwoViewGeometry::EstimateCalibrated).
COLMAP_MAX_ERROR = 4.0
CALIBRATED = 2


def colmap_sampson(f, x1, x2):
    h1, h2 = np.hstack([x1, np.ones((len(x1), 1))]), np.hstack([x2, np.ones((len(x2), 1))])
    fx1, ftx2 = h1 @ f.T, h2 @ f
    return np.abs(np.sum(h2 * fx1, axis=1)) / np.sqrt(np.sum(fx1[:, :2] ** 2, axis=1) + np.sum(ftx2[:, :2] ** 2, axis=1))


def stored_geometries(database):
    """{(name1, name2): (config, inliers M x 2, F, E, keypoints1 M x 2, keypoints2, camera1, camera2)}
    of every pair with inliers, read from the blobs as COLMAP reads them."""
    con = sqlite3.connect(database)
    try:
        names = dict(con.execute("SELECT image_id, name FROM images"))
        camera_of = dict(con.execute("SELECT image_id, camera_id FROM images"))
        cameras = {cid: (model, np.frombuffer(p, np.float64)) for cid, model, p in con.execute(
            "SELECT camera_id, model, params FROM cameras")}
        keypoints = {iid: np.frombuffer(d, np.float32).reshape(r, c)[:, :2].astype(np.float64)
                     for iid, r, c, d in con.execute("SELECT image_id, rows, cols, data FROM keypoints")}
        out = {}
        for pid, rows, cols, data, config, f, e in con.execute(
                "SELECT pair_id, rows, cols, data, config, F, E FROM two_view_geometries WHERE rows > 0"):
            id1, id2 = pid // 2147483647, pid % 2147483647
            m = np.frombuffer(data, np.uint32).reshape(rows, cols).astype(np.int64)
            out[(names[id1], names[id2])] = (config, m, np.frombuffer(f, np.float64).reshape(3, 3),
                                             np.frombuffer(e, np.float64).reshape(3, 3), keypoints[id1][m[:, 0]],
                                             keypoints[id2][m[:, 1]], cameras[camera_of[id1]], cameras[camera_of[id2]])
        return out
    finally:
        con.close()


def beyond_colmaps_threshold(geometry):
    """How many inliers lie beyond COLMAP's threshold of the stored F (pixels) or E (normalised)."""
    config, m, f, e, x1, x2, (model1, k1), (model2, k2) = geometry
    assert model1 == model2 == 1  # PINHOLE: fx, fy, cx, cy
    n1 = (x1 - k1[2:4]) / k1[0:2]
    n2 = (x2 - k2[2:4]) / k2[0:2]
    e_threshold = (COLMAP_MAX_ERROR / k1[0:2].mean() + COLMAP_MAX_ERROR / k2[0:2].mean()) / 2.0
    return int(np.sum((colmap_sampson(f, x1, x2) > COLMAP_MAX_ERROR) | (colmap_sampson(e, n1, n2) > e_threshold)))


def model_analyzer(path):
    out = subprocess.run(["colmap", "model_analyzer", "--path", str(path)], stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, universal_newlines=True, timeout=300).stdout
    value = lambda key: float(out.split(key + ":")[1].split()[0].rstrip("px"))
    return int(value("Registered images")), int(value("Points")), value("Mean reprojection error")


def test_what_the_guided_matcher_stores_is_what_colmap_would_verify(kitchen):
    project = kitchen / "guided"
    report = json.load(open(str(project / "report.json")))
    paths = report["matching"]["pairs"]
    geometries = stored_geometries(str(project / "database.db"))
    guided_pairs = {tuple(sorted(k.split())) for k, s in paths.items() if s["path"] in (guided.GUIDED, guided.IMAGES)}
    assert len(guided_pairs) > 0.8 * report["pairs_matched"]
    checked = 0
    for pair, geometry in sorted(geometries.items()):
        if tuple(sorted(pair)) not in guided_pairs:
            continue  # a fallback pair: COLMAP's matches_importer verified it with its own geometry
        assert geometry[0] == CALIBRATED, pair
        assert beyond_colmaps_threshold(geometry) == 0, "%s: inliers beyond %g px of the stored geometry" % (
            pair, COLMAP_MAX_ERROR)
        checked += len(geometry[1])
    assert len([p for p in geometries if tuple(sorted(p)) in guided_pairs]) == len(guided_pairs)
    assert checked >= 15 * len(guided_pairs)

    # COLMAP's own point_triangulator reads the database (keypoints, verified pairs) and
    # triangulates the known-pose model's keyframes from it alone (the model's points cleared).
    out = kitchen / "colmap_triangulated"
    out.mkdir()
    run(["colmap", "point_triangulator", "--database_path", str(project / "database.db"),
         "--image_path", str(project / "images"), "--input_path", str(project / "sparse" / "0"),
         "--clear_points", "1", "--output_path", str(out)])
    # Measured: 3,805 points at 1.63 px, against the live model's 5,345 at 1.31 px from the same
    # database (COLMAP's own pipeline on these pairs: 3,274 at 1.67 px); the bounds leave a margin.
    registered, points, error = model_analyzer(out)
    assert registered == report["registered"] == report["keyframes"]
    assert points >= 0.5 * report["points"], (points, report["points"])
    assert error < 2.0
