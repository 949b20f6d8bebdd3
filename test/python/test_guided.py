"""Pose-guided matching: on synthetic features with exact correspondences, and with real SIFT on
two rendered views of a textured plane. No ROS, no COLMAP."""
import math

import cv2
import numpy as np
import pytest

from view_selection import geometry
from view_selection.features.sift import Features, SiftExtractor
from view_selection.keyframes import Keyframe
from view_selection.matching import guided, two_view

K = (500.0, 500.0, 320.0, 240.0)


def look_at(i, centre, target, up=(0, -1, 0)):
    """A keyframe at `centre` looking at `target` (optical frame: z forward, y down)."""
    z = np.asarray(target, float) - centre
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z], axis=1)  # camera -> world
    return Keyframe(i, "%d.png" % i, float(i), centre, geometry.quaternion_of(r), K, 640, 480)


def project(k, points):
    q, t = geometry.world_to_camera(k.position, k.orientation)
    pc = points @ geometry.rotation_of(q).T + t
    fx, fy, cx, cy = k.intrinsics
    return np.stack([fx * pc[:, 0] / pc[:, 2] + cx, fy * pc[:, 1] / pc[:, 2] + cy], axis=1), pc[:, 2]


def synthetic_pair(n=1500, seed=0, noise_px=0.5, distractors=500):
    rng = np.random.default_rng(seed)
    points = rng.uniform([-2, -1.5, 3], [2, 1.5, 6], (n, 3))
    a = look_at(0, np.array([0.0, 0.0, 0.0]), [0, 0, 4.5])
    b = look_at(1, np.array([0.4, 0.05, 0.1]), [0, 0, 4.5])
    xa, za = project(a, points)
    xb, zb = project(b, points)
    seen = (za > 0) & (zb > 0) & np.all((xa >= 0) & (xa < [640, 480]), 1) & np.all((xb >= 0) & (xb < [640, 480]), 1)
    points, xa, xb = points[seen], xa[seen], xb[seen]
    desc = rng.normal(size=(len(points), 128)).astype(np.float32)
    desc_b = desc + rng.normal(scale=0.25, size=desc.shape).astype(np.float32)  # the same point, seen again
    extra = rng.normal(size=(distractors, 128)).astype(np.float32)
    unit = lambda d: d / np.linalg.norm(d, axis=1, keepdims=True)
    fa = Features(xa + rng.normal(scale=noise_px, size=xa.shape), np.ones(len(xa)), np.zeros(len(xa)), unit(desc))
    xb_all = np.vstack([xb + rng.normal(scale=noise_px, size=xb.shape), rng.uniform([0, 0], [640, 480], (distractors, 2))])
    fb = Features(xb_all, np.ones(len(xb_all)), np.zeros(len(xb_all)), unit(np.vstack([desc_b, extra])))
    return a, b, fa, fb, len(points)


def test_exact_poses_find_the_true_correspondences():
    a, b, fa, fb, n = synthetic_pair()
    r = guided.match_pair(fa, fb, a, b)
    assert r.path == guided.GUIDED, r.why
    correct = np.sum(r.inliers[:, 0] == r.inliers[:, 1])  # feature i of a is point i, so is feature i of b
    assert correct >= 0.9 * n
    assert correct >= 0.99 * len(r.inliers)  # the distractors are not matched
    assert r.band_px <= 4.0 + 1e-9  # exact poses: the narrowest band


def test_every_inlier_lies_within_the_band_of_the_poses_epipolar_lines():
    a, b, fa, fb, _ = synthetic_pair(noise_px=1.5, seed=3)
    r = guided.match_pair(fa, fb, a, b)
    assert r.path == guided.GUIDED
    d = guided.epipolar_distances(r.guide_F, fa.xy[r.inliers[:, 0]], fb.xy[r.inliers[:, 1]])
    assert np.all(np.diag(d) <= r.band_px + 1e-6)


def test_every_inlier_lies_within_colmaps_threshold_of_the_stored_geometry():
    """Poses 2 cm off widen the band beyond COLMAP's 4 px; the geometry stored for the pair is
    the one the matches give, and every inlier is within 4 px (Sampson) of its F at the
    keypoints as the database holds them, and in front of both cameras."""
    a, b, fa, fb, n = synthetic_pair(seed=1, noise_px=1.0)
    off = Keyframe(b.id, b.name, b.stamp, np.asarray(b.position) + [0.0, 0.02, 0.0], b.orientation, b.intrinsics,
                   b.width, b.height)
    r = guided.match_pair(fa, fb, a, off)
    assert r.path == guided.GUIDED, r.why
    assert r.band_px > two_view.COLMAP_MAX_ERROR_PX
    xa, xb = fa.xy[r.inliers[:, 0]] + 0.5, fb.xy[r.inliers[:, 1]] + 0.5  # COLMAP's keypoints
    assert np.all(two_view.sampson_distances(r.geometry.F, xa, xb) <= two_view.COLMAP_MAX_ERROR_PX)
    assert np.all(two_view.in_front(*(two_view.normalised(x, two_view.colmap_intrinsic_matrix(k))
                                      for x, k in ((xa, a), (xb, off))), r.geometry.R, r.geometry.t))
    assert np.sum(r.inliers[:, 0] == r.inliers[:, 1]) >= 0.8 * n  # the matcher's matches stay
    # E, R, t and F are one geometry: E = [t]x R, F = K_b^-T E K_a^-1 with the database's cameras
    g = r.geometry
    unit = lambda m: m / np.linalg.norm(m) * np.sign(m.flat[np.argmax(np.abs(m))])
    assert np.allclose(unit(g.E), unit(guided.skew(g.t) @ g.R), atol=1e-6)
    ka, kb = two_view.colmap_intrinsic_matrix(a), two_view.colmap_intrinsic_matrix(off)
    assert np.allclose(unit(g.F), unit(np.linalg.inv(kb).T @ g.E @ np.linalg.inv(ka)), atol=1e-9)


def test_one_triangulation_gives_the_cheirality_of_t_and_minus_t():
    """estimate() triangulates once for t and -t: the depths with -t are those with t, negated.
    Checked against a triangulation of its own for -t, on correspondences in front, behind and
    on both sides of a pair of cameras, at each rotation of an essential matrix's decomposition."""
    rng = np.random.default_rng(3)
    r_true = cv2.Rodrigues(np.array([0.05, -0.2, 0.03]))[0]
    t_true = np.array([0.3, 0.02, -0.1])
    x = rng.uniform([-2, -2, -3], [2, 2, 6], (300, 3))  # some behind a, some behind b
    xb = x @ r_true.T + t_true
    na, nb = x[:, :2] / x[:, 2:], xb[:, :2] / xb[:, 2:]
    e = guided.skew(t_true / np.linalg.norm(t_true)) @ r_true
    r1, r2, t = cv2.decomposeEssentialMat(e)
    mixed = 0
    for r in (r1, r2):
        za, zb = two_view.depths(na, nb, r, t)
        finite = np.isfinite(za) & np.isfinite(zb)
        assert np.array_equal(two_view.in_front(na, nb, r, t), finite & (za > 0) & (zb > 0))
        assert np.array_equal(two_view.in_front(na, nb, r, -t), finite & (za < 0) & (zb < 0))
        mixed += int(np.sum(finite & (za > 0) & (zb < 0)))
    assert mixed > 0  # a sign of one depth alone does not tell: both are looked at


def test_the_stored_geometry_is_the_poses_in_colmaps_pixel_convention():
    """Noise-free correspondences at exact poses: the stored E is the poses' (E does not depend on
    the pixel convention), and the stored F is the poses' moved to COLMAP's pixel centres (x + 0.5):
    T^-T F T^-1 with T the half-pixel shift. Measured: equal to 3e-16; the poses' F as the matcher
    uses it (OpenCV's convention) differs by 2e-4, so the comparison sees the half pixel."""
    a, b, fa, fb, _ = synthetic_pair(seed=0, noise_px=0.0)
    r = guided.match_pair(fa, fb, a, b)
    assert r.path == guided.GUIDED, r.why
    unit = lambda m: m / np.linalg.norm(m) * np.sign(m.flat[np.argmax(np.abs(m))])
    rotation, t = guided.relative_pose(a, b)
    assert np.allclose(unit(r.geometry.E), unit(guided.skew(t) @ rotation), atol=1e-9)
    shift = np.linalg.inv(np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]]))
    assert np.allclose(unit(r.geometry.F), unit(shift.T @ r.guide_F @ shift), atol=1e-9)
    assert np.abs(unit(r.geometry.F) - unit(r.guide_F)).max() > 1e-5


def test_poses_a_little_off_widen_the_band():
    a, b, fa, fb, n = synthetic_pair(seed=1)
    c = np.asarray(b.position) + [0.0, 0.02, 0.0]  # 2 cm off across the baseline: a few pixels
    off = Keyframe(b.id, b.name, b.stamp, c, b.orientation, b.intrinsics, b.width, b.height)
    r = guided.match_pair(fa, fb, a, off)
    assert r.path == guided.GUIDED, r.why
    assert r.band_px > 4.0
    assert np.sum(r.inliers[:, 0] == r.inliers[:, 1]) >= 0.8 * n


def tilted(b, angle=0.05):
    """b's pose tilted about its x axis: by 0.05 (5.7 degrees) every point moves across the (near
    horizontal) epipolar lines by about 50 px, further than the window. (A pan would move them
    along the lines, where an epipolar constraint cannot see a pose error.)"""
    turn = geometry.rotation_of(b.orientation) @ geometry.rotation_of((math.cos(angle), math.sin(angle), 0, 0))
    return Keyframe(b.id, b.name, b.stamp, b.position, geometry.quaternion_of(turn), b.intrinsics, b.width, b.height)


def test_poses_that_disagree_with_the_images_are_matched_by_the_images_geometry():
    """The poses find no match within their window; the strongest features matched without them
    give the geometry that guides instead (path 'images'), and the matches are the true ones,
    as many as exact poses give."""
    a, b, fa, fb, n = synthetic_pair(seed=2)
    exact = guided.match_pair(fa, fb, a, b)
    r = guided.match_pair(fa, fb, a, tilted(b))
    assert r.path == guided.IMAGES, r.why
    assert "epipolar" in r.why and r.summary()["why"] == r.why
    correct = np.sum(r.inliers[:, 0] == r.inliers[:, 1])
    assert correct >= 0.99 * len(r.inliers) and correct >= 0.95 * len(exact.inliers)
    # The band is the images' geometry's, not the tilted poses': the inliers lie within it of the
    # guide, and far from the poses' lines.
    d = np.diag(guided.epipolar_distances(r.guide_F, fa.xy[r.inliers[:, 0]], fb.xy[r.inliers[:, 1]]))
    assert np.all(d <= r.band_px + 1e-6)
    rotation, t = guided.relative_pose(a, tilted(b))
    poses_f = guided.fundamental_of_motion(rotation, t, guided.intrinsic_matrix(a), guided.intrinsic_matrix(b))
    assert np.median(np.diag(guided.epipolar_distances(poses_f, fa.xy[r.inliers[:, 0]], fb.xy[r.inliers[:, 1]]))) > 10


def test_poses_that_disagree_with_images_that_do_not_match_are_not_handed_to_colmap():
    """Neither the poses nor the images give a geometry, and b's features are not a's points:
    fewer than min_inliers of them pass COLMAP's own matching tests, so COLMAP's matcher could
    not verify the pair either. It is not verified (path 'unmatched'), with why, and its matches
    are those COLMAP's tests pass."""
    a, b, fa, fb, _ = synthetic_pair(seed=2)
    rng = np.random.default_rng(7)
    other = rng.normal(size=fb.descriptors.shape).astype(np.float32)
    fb = Features(fb.xy, np.ones(len(fb.xy)), np.zeros(len(fb.xy)), other / np.linalg.norm(other, axis=1, keepdims=True))
    r = guided.match_pair(fa, fb, a, tilted(b))
    assert r.path == guided.UNMATCHED, r.why
    assert "epipolar" in r.why and "pass COLMAP's tests" in r.why
    loose = guided.mutual_ratio_matches(fa.descriptors @ fb.descriptors.T, 0.8, 0.7)
    assert len(loose) < 15
    np.testing.assert_array_equal(loose, r.matches)
    assert len(r.inliers) == 0 and r.geometry is None


def test_poses_that_disagree_with_features_that_match_without_a_geometry_fall_back():
    """The features match (a's points, seen again) but their places in b give no geometry (b's
    keypoints scattered at random), and the poses disagree: enough matches pass COLMAP's tests
    for its matcher to try, so the pair goes to it, with why."""
    a, b, fa, fb, n = synthetic_pair(seed=2, n=150, distractors=100)
    rng = np.random.default_rng(5)
    xy = fb.xy.copy()
    xy[:n] = rng.uniform([0, 0], [640, 480], (n, 2))
    fb = Features(xy, np.ones(len(xy)), np.zeros(len(xy)), fb.descriptors)
    r = guided.match_pair(fa, fb, a, tilted(b))
    assert r.path == guided.FALLBACK, r.why
    assert "epipolar" in r.why and "inliers of" not in r.why
    assert len(guided.mutual_ratio_matches(fa.descriptors @ fb.descriptors.T, 0.8, 0.7)) >= 15


def repeated_texture_on_the_poses_lines(a, fa, fb, poses_b, copies=25, seed=11):
    """fb with a look-alike of the first `copies` of a's points put in front: each the same
    descriptor as the point's own feature in b (a repeated texture), placed where the poses
    (a, poses_b) put the point at a wrong depth, so on the poses' epipolar line of a's feature
    while its true match lies off it. Returns the features (b's own feature i is now copies + i)."""
    rng = np.random.default_rng(seed)
    q, t = geometry.world_to_camera(a.position, a.orientation)
    ra = geometry.rotation_of(q)
    fx, fy, cx, cy = a.intrinsics
    xy = []
    for i in range(copies):
        ray = np.array([(fa.xy[i, 0] - cx) / fx, (fa.xy[i, 1] - cy) / fy, 1.0])
        for depth in rng.uniform(1.5, 9.0, 50):
            point = ra.T @ (ray * depth - t)  # a's ray at a wrong depth, in the world
            x, z = project(poses_b, point[None, :])
            if z[0] > 0 and np.all((x[0] >= 0) & (x[0] < [640, 480])) and np.linalg.norm(x[0] - fb.xy[i]) > 30:
                xy.append(x[0])
                break
    n = len(xy)
    look_alike = fb.descriptors[:n] + rng.normal(scale=0.01, size=(n, 128)).astype(np.float32)
    look_alike /= np.linalg.norm(look_alike, axis=1, keepdims=True)
    return n, Features(np.vstack([np.array(xy), fb.xy]), np.ones(n + len(fb)), np.zeros(n + len(fb)),
                       np.vstack([look_alike, fb.descriptors]).astype(np.float32))


def test_a_repeated_texture_along_poses_that_are_off_is_confirmed_by_the_images():
    """Drift across a revisit with a repeated texture: the true matches lie beyond the window of
    the poses' lines, and 25 look-alikes lie on them. Within the window the look-alikes pass the
    strict ratio test (their twins are outside it) and verify against the poses' own geometry;
    trusted, they were a wrong two-view geometry in the database (a 30-minute walk had 17, each
    with 15-28 inliers, and the refinement followed them metres off). Fewer than confirm_inliers
    matches near the lines: the images confirm, and their geometry is the true one."""
    a, b, fa, fb, n = synthetic_pair(seed=2)
    off = tilted(b)
    copies, fb = repeated_texture_on_the_poses_lines(a, fa, fb, off)
    assert copies >= 20
    trusted = guided.match_pair(fa, fb, a, off, guided.GuidedOptions(confirm_inliers=0))
    assert trusted.path == guided.GUIDED and 15 <= len(trusted.inliers) < 30  # what the poses alone verify
    assert np.sum(trusted.inliers[:, 1] == trusted.inliers[:, 0] + copies) <= 0.2 * len(trusted.inliers)
    r = guided.match_pair(fa, fb, a, off)
    assert r.path == guided.IMAGES and "the images confirm" in r.why, r.why
    correct = np.sum(r.inliers[:, 1] == r.inliers[:, 0] + copies)
    assert correct >= 0.99 * len(r.inliers) and correct >= 0.8 * n


def test_poses_that_agree_with_the_images_are_not_confirmed_again():
    """Many matches near exact poses' lines: the poses guide, the images are not asked."""
    a, b, fa, fb, _ = synthetic_pair(seed=3)
    r = guided.match_pair(fa, fb, a, b)
    assert r.path == guided.GUIDED and r.searched >= 30 and len(r.inliers) >= 30 and r.why == ""


def test_no_baseline_falls_back():
    a, _, fa, fb, _ = synthetic_pair()
    r = guided.match_pair(fa, fb, a, a)
    assert r.path == guided.FALLBACK and "baseline" in r.why


def test_features_round_trip_through_colmaps_format():
    rng = np.random.default_rng(4)
    d = rng.random((20, 128)).astype(np.float32)
    f = Features(rng.uniform(0, 600, (20, 2)), rng.uniform(1, 5, 20), rng.uniform(-3, 3, 20),
                 d / np.linalg.norm(d, axis=1, keepdims=True))
    kp, desc = f.to_colmap()
    assert kp.dtype == np.float32 and kp.shape == (20, 4) and desc.dtype == np.uint8 and desc.shape == (20, 128)
    assert np.allclose(kp[:, :2], f.xy + 0.5, atol=1e-4)  # COLMAP's pixel centres
    back = Features.from_colmap(kp, desc)
    assert np.allclose(back.xy, f.xy, atol=1e-4)
    assert np.all(np.sum(back.descriptors * f.descriptors, axis=1) > 0.999)  # uint8 quantisation only


def textured_plane_views():
    """Two renderings of a textured plane z = 3 m, and the homography between them."""
    rng = np.random.default_rng(5)
    texture = cv2.GaussianBlur((rng.random((1200, 1600)) * 255).astype(np.uint8), (0, 0), 2.0)
    texture = cv2.equalizeHist(texture)
    a = look_at(0, np.array([0.0, 0.0, 0.0]), [0, 0, 3])
    b = look_at(1, np.array([0.3, -0.05, 0.05]), [0.05, 0, 3])
    # the plane's texture coordinates: x, y in [-2, 2] x [-1.5, 1.5] m -> 1600 x 1200 px
    plane_to_texture = np.array([[400.0, 0, 800], [0, 400.0, 600], [0, 0, 1]])
    images, homographies = [], []
    for k in (a, b):
        q, t = geometry.world_to_camera(k.position, k.orientation)
        r = geometry.rotation_of(q)
        kk = guided.intrinsic_matrix(k)
        plane_to_image = kk @ np.column_stack([r[:, 0], r[:, 1], r[:, 2] * 3.0 + t])  # (X, Y, 1) on z = 3
        h = plane_to_image @ np.linalg.inv(plane_to_texture)
        images.append(cv2.warpPerspective(texture, h, (640, 480), flags=cv2.INTER_LINEAR))
        homographies.append(h)
    return a, b, images, homographies[1] @ np.linalg.inv(homographies[0])


def test_real_sift_on_a_rendered_plane_gives_correct_inliers():
    a, b, (ia, ib), a_to_b = textured_plane_views()
    extractor = SiftExtractor(max_features=2048)
    fa, fb = extractor.extract(ia), extractor.extract(ib)
    assert len(fa) > 500 and len(fb) > 500
    r = guided.match_pair(fa, fb, a, b)
    assert r.path == guided.GUIDED, r.why
    moved = cv2.perspectiveTransform(fa.xy[r.inliers[:, 0]].reshape(-1, 1, 2), a_to_b).reshape(-1, 2)
    error = np.linalg.norm(moved - fb.xy[r.inliers[:, 1]], axis=1)
    assert len(r.inliers) >= 200
    assert np.mean(error < 2.0) >= 0.98


def test_an_unreadable_image_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(ValueError, match="cannot read"):
        SiftExtractor().extract_file(str(bad))


def test_fewer_features_than_colmap_verifies_are_not_handed_to_it():
    a, b, fa, fb, _ = synthetic_pair()
    few = Features(fb.xy[:14], fb.scale[:14], fb.orientation[:14], fb.descriptors[:14])
    r = guided.match_pair(fa, few, a, b)
    assert r.path == guided.UNMATCHED and "fewer than 15 features" in r.why
    assert len(r.matches) == 0 and len(r.inliers) == 0
