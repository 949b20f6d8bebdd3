"""Pose-guided matching of two keyframes: search where the node's poses say a match lies, within
a band that follows how well the poses agree with the images, and say when they do not.

For keyframes a and b with camera-to-world poses, the relative pose (x_b = R x_a + t) gives the
fundamental matrix F = K_b^-T [t]x R K_a^-1: a feature at x_a matches a feature of b near its
epipolar line F x_a.

  1. Search: the strongest `search_features` features of a against those of b within the window
     of their epipolar lines (`window_deg` of view angle, f tan(window_deg) pixels: what the
     poses can be off by and still guide, drift between keyframes close in time; 15 px at VGA),
     with a strict ratio test (`strict_ratio`) and a mutual check: matches that are very likely
     right. Fewer than `min_inliers` of them: the poses disagree with the images (drift before a
     loop closes, a wrong pose). Fewer than `confirm_inliers` of them, or fewer inliers in step
     4, and the images confirm (step 1', path 'images' or what follows from it): the window keeps
     the look-alikes elsewhere in the image out of the ratio test, so where drift puts the lines
     beside the true matches, a repeated texture can give `min_inliers` matches along them that
     verify against the poses' own geometry. On a 30-minute walk on odometry 17 of 2,478 guided
     pairs were such (15-28 inliers; the rendered poses put their matches 5-49 px off the true
     epipolar geometry, median) and the refinement followed them metres off; confirmed by the
     images, none of the 220 pairs below 30 kept a wrong geometry (of the 17, 16 took the
     images' geometry, true, and 1 went to COLMAP's matcher; docs/design.md).
  1'. Then the images guide instead (path 'images'): the same strongest features matched without
     the poses (strict ratio, mutual), and the geometry those give (two_view.estimate, at least
     `min_inliers` inliers) is the epipolar geometry of steps 2-4, as COLMAP's guided matching
     uses the geometry its matches gave. On a 10-minute walk on odometry, 2,045 of 7,992 pairs
     had fewer than 15 matches within 7 px of the poses' lines (median 4, most of them across a
     revisit 5-30 s apart); COLMAP's matcher then verified 1,925 of them, with a median of 166
     inliers, at 0.049 s of CPU a pair against 0.009 here. When the images give no geometry
     either, the pair falls back to COLMAP's unguided matching (matches_importer), unless fewer
     than `min_inliers` of its features pass COLMAP's matching tests without the poses (path
     'unmatched'): COLMAP could not verify it, and it is written as COLMAP writes a pair that
     does not verify.
  2. The band: how far those matches lie from the poses' epipolar lines (their 90th percentile,
     plus a pixel), at least `band_px` (COLMAP 3.8's two-view verification allows 4 px) and at
     most the window. Good poses give a narrow band, drifting ones a wider one.
  3. Match every feature within the band, with COLMAP's ratio (0.8) and distance (0.7) tests and
     the mutual check; the ratio test's second best is looked for in the whole window (a feature
     with a look-alike along its epipolar line is ambiguous: measured, this gives both more
     points and a lower reprojection error than a second best from the band alone, docs/live.md).
  4. Verify as COLMAP does (two_view.py): the geometry the matches give, estimated with COLMAP's
     threshold (4 px), and the matches within it and in front of both cameras are the inliers (at
     least COLMAP's min_num_inliers, 15, or the pair falls back). The band may be wider than 4 px
     where the poses drift; what COLMAP reads as verified may not.

Descriptor distances are angles between unit RootSIFT descriptors, as COLMAP's matcher measures
them. The search is a dense product of the two descriptor matrices with the band as a mask: for
2,000 features a side about 0.03 s of one core (docs/live.md).
"""

import math

import numpy as np

from .. import geometry
from . import two_view

GUIDED, IMAGES, FALLBACK, UNMATCHED = "guided", "images", "fallback", "unmatched"


class GuidedOptions:
    def __init__(self, window_deg=1.5, band_px=4.0, ratio=0.8, strict_ratio=0.7, max_distance=0.7, min_inliers=15,
                 search_features=512, confirm_inliers=30):
        self.window_deg, self.band_px = float(window_deg), float(band_px)
        self.search_features = int(search_features)
        self.ratio, self.strict_ratio, self.max_distance = float(ratio), float(strict_ratio), float(max_distance)
        self.min_inliers = int(min_inliers)
        self.confirm_inliers = int(confirm_inliers)


class PairResult:
    """path: 'guided' or 'images' (inliers verified here), 'fallback' (why: the poses cannot be
    trusted, or the matches do not verify: COLMAP's matcher is to try) or 'unmatched' (fewer
    matches than COLMAP could verify, with or without the poses: not verified). matches: the
    putative matches of step 3 (M x 2 indices into a's and b's features; on the path 'unmatched'
    those COLMAP's tests pass); inliers: the verified ones; geometry: what they verify against
    (two_view.TwoViewGeometry: E, F in COLMAP's pixel convention, R, t), the one the database
    gets; guide_F: the fundamental matrix that guided the search (the poses', or on the path
    'images' the one the strongest features gave) in the features' (OpenCV's) pixel convention, the
    band's reference; band_px: the band used; searched: the matches of step 1."""

    def __init__(self, path, why="", matches=None, geometry=None, guide_F=None, band_px=None, searched=0):
        self.path, self.why = path, why
        self.matches = np.zeros((0, 2), np.int64) if matches is None else matches
        self.geometry = geometry
        self.inliers = np.zeros((0, 2), np.int64) if geometry is None else geometry.inliers
        self.guide_F = guide_F
        self.band_px, self.searched = band_px, searched

    def summary(self):
        out = {"path": self.path, "inliers": int(len(self.inliers)), "searched": int(self.searched)}
        if self.why:
            out["why"] = self.why
        if self.band_px is not None:
            out["band_px"] = round(float(self.band_px), 2)
        return out


def intrinsic_matrix(keyframe):
    fx, fy, cx, cy = keyframe.intrinsics
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def relative_pose(a, b):
    """(R, t) with x_b = R x_a + t, from two keyframes' camera-to-world poses."""
    qa, ta = geometry.world_to_camera(a.position, a.orientation)
    qb, tb = geometry.world_to_camera(b.position, b.orientation)
    ra, rb = geometry.rotation_of(qa), geometry.rotation_of(qb)
    r = rb @ ra.T
    return r, np.asarray(tb) - r @ np.asarray(ta)


def skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fundamental(e, ka, kb):
    return np.linalg.inv(kb).T @ e @ np.linalg.inv(ka)


def fundamental_of_motion(r, t, ka, kb):
    """F of the relative pose x_b = R x_a + t (t of any non-zero length) and the intrinsic matrices."""
    return fundamental(skew(t / np.linalg.norm(t)) @ r, ka, kb)


def epipolar_distances(f, xa, xb):
    """|distance| of each feature of b (columns) to the epipolar line of each feature of a (rows)
    [px], float32."""
    ha = np.hstack([xa, np.ones((len(xa), 1))]).astype(np.float32)
    hb = np.hstack([xb, np.ones((len(xb), 1))]).astype(np.float32)
    lines = ha @ f.T.astype(np.float32)
    norm = np.linalg.norm(lines[:, :2], axis=1, keepdims=True)
    lines /= np.maximum(norm, 1e-12)
    return np.abs(lines @ hb.T)


def mutual_ratio_matches(similarity, ratio, max_distance, competitors=None):
    """Mutual best matches passing the ratio and distance tests on angular distances (M x 2 row,
    column). `similarity` holds cosines, -1 where masked out; the second best of the ratio test
    comes from `competitors` (a wider mask of the same cosines; default `similarity`). Both are
    scratch space (changed, then restored)."""
    n = similarity.shape[0]
    if n == 0 or similarity.shape[1] == 0:
        return np.zeros((0, 2), np.int64)
    competitors = similarity if competitors is None else competitors
    rows = np.arange(n)
    best = similarity.argmax(axis=1)
    first = similarity[rows, best].copy()
    if similarity.shape[1] > 1:
        kept = competitors[rows, best].copy()
        competitors[rows, best] = -1.0
        second = competitors.max(axis=1)
        competitors[rows, best] = kept
    else:
        second = np.full(n, -1.0, np.float32)
    d1 = np.arccos(np.clip(first, -1.0, 1.0))
    d2 = np.arccos(np.clip(second, -1.0, 1.0))
    i = np.nonzero((first > -1.0) & (d1 <= max_distance) & (d1 < ratio * d2))[0]
    j = best[i]
    if len(i) == 0:
        return np.zeros((0, 2), np.int64)
    # mutual: row i is the best of its column j (only the chosen columns are looked at)
    columns, inverse = np.unique(j, return_inverse=True)
    column_best = similarity[:, columns].argmax(axis=0)
    keep = column_best[inverse] == i
    return np.stack([i[keep], j[keep]], axis=1).astype(np.int64)


def match_pair(fa, fb, ka, kb, options=None):
    """Pose-guided matching of features fa, fb (features.sift.Features) of keyframes ka, kb."""
    o = options or GuidedOptions()
    if len(fa) < o.min_inliers or len(fb) < o.min_inliers:
        return PairResult(UNMATCHED, "fewer than %d features: COLMAP could not verify it either" % o.min_inliers)
    result = _match(fa, fb, ka, kb, o, trust_poses=True)
    if result.path == GUIDED and min(result.searched, len(result.inliers)) < o.confirm_inliers:
        # Few matches near the poses' lines, or few inliers: the images confirm (step 1'). The
        # window keeps look-alikes elsewhere in the image out of the ratio test, so where the poses
        # are off (drift across a revisit) a repeated texture can give min_inliers matches along
        # their lines, which then verify against the poses' own geometry.
        return _match(fa, fb, ka, kb, o, trust_poses=False,
                      why="%d matches within the window of the poses' epipolar lines, %d inliers: "
                          "fewer than %d, the images confirm" % (result.searched, len(result.inliers),
                                                                  o.confirm_inliers))
    return result


def _match(fa, fb, ka, kb, o, trust_poses, why=""):
    """Steps 1-4; without trust_poses, step 1 is skipped: the images guide (step 1')."""
    r, t = relative_pose(ka, kb)
    baseline = float(np.linalg.norm(t))
    if not baseline > 1e-9:
        return PairResult(FALLBACK, "no baseline between the poses")
    kma, kmb = intrinsic_matrix(ka), intrinsic_matrix(kb)
    window = max(o.band_px, math.sqrt(kmb[0, 0] * kmb[1, 1]) * math.tan(math.radians(o.window_deg)))
    f = fundamental_of_motion(r, t, kma, kmb)
    # One descriptor product and one distance matrix for steps 1 and 3: step 1 reads their block of
    # the strongest features (all of them at QVGA, where a keyframe has 300-600 features), step 3
    # the whole; computed twice they were about half of a guided pair's CPU.
    cosines = fa.descriptors @ fb.descriptors.T
    distances = epipolar_distances(f, fa.xy, fb.xy)
    # 1. the poses' search window, strict tests, the strongest features
    na1, nb1 = min(len(fa), o.search_features), min(len(fb), o.search_features)
    strong = cosines[:na1, :nb1]
    searched = mutual_ratio_matches(np.where(distances[:na1, :nb1] <= window, strong, np.float32(-1.0)),
                                    o.strict_ratio, o.max_distance)
    path = GUIDED
    if not trust_poses or len(searched) < o.min_inliers:
        # 1'. The poses disagree with the images (drift across a revisit): the strongest features
        # matched without them, and the geometry those give guides instead, as COLMAP's guided
        # matching does, when it holds min_inliers; else COLMAP's matcher (5 times the CPU).
        why = why or "%d matches within %.0f px of the poses' epipolar lines" % (len(searched), window)
        unguided = mutual_ratio_matches(strong.copy(), o.strict_ratio, o.max_distance)
        coarse = two_view.estimate(unguided, fa, fb, ka, kb) if len(unguided) >= o.min_inliers else None
        if coarse is None or len(coarse.inliers) < o.min_inliers or not np.linalg.norm(coarse.t) > 1e-12:
            # 1''. COLMAP's matcher would match every feature with its own tests (ratio, distance,
            # cross-check: a subset of these mutual matches) and verify at least min_inliers of
            # them: where fewer pass, it cannot verify the pair, and is not started for it (on a
            # 30-minute walk 353 of 439 such pairs; COLMAP verified none of them, docs/live.md).
            loose = mutual_ratio_matches(cosines, o.ratio, o.max_distance)
            if len(loose) < o.min_inliers:
                return PairResult(UNMATCHED, why + "; %d matches pass COLMAP's tests without the poses" % len(loose),
                                  matches=loose, searched=len(searched))
            return PairResult(FALLBACK, why, searched=len(searched))
        path, searched = IMAGES, coarse.inliers
        f = fundamental_of_motion(coarse.R, coarse.t, kma, kmb)
        distances = epipolar_distances(f, fa.xy, fb.xy)
    # 2. the band those matches need
    band = float(min(window, max(o.band_px, np.percentile(distances[searched[:, 0], searched[:, 1]], 90) + 1.0)))
    # 3. every feature within the band, COLMAP's tests; the ratio test against every candidate
    # the window allows (a feature with a look-alike along its epipolar line is ambiguous, even
    # when the look-alike lies outside the band)
    similarity = cosines
    similarity[distances > window] = -1.0
    in_band = np.where(distances <= band, similarity, np.float32(-1.0))
    matches = mutual_ratio_matches(in_band, o.ratio, o.max_distance, competitors=similarity)
    # 4. verified as COLMAP verifies: within its threshold of the geometry the matches give
    verified = two_view.estimate(matches, fa, fb, ka, kb)
    count = 0 if verified is None else len(verified.inliers)
    if count < o.min_inliers:
        return PairResult(FALLBACK, (why + "; " if why else "") +
                          "%d inliers of %d matches within %.1f px (within %.0f px of the geometry they give)"
                          % (count, len(matches), band, two_view.COLMAP_MAX_ERROR_PX), matches=matches, guide_F=f,
                          band_px=band, searched=len(searched))
    return PairResult(path, why, matches=matches, geometry=verified, guide_F=f, band_px=band, searched=len(searched))
