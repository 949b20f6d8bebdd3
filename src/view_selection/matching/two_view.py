"""The two-view geometry a guided pair stores in the database: what COLMAP 3.8's own verification
would accept of the guided matches.

The guided matcher accepts matches within its band of the poses' epipolar lines, up to the
search window (15 px at VGA) where the poses drift. COLMAP reads a CALIBRATED two-view geometry's
inliers as verified, and its own verification (TwoViewGeometry, RANSAC max_error 4 px, on the
squared Sampson error) keeps only matches within 4 px of the geometry the images give. So the
geometry stored here is estimated from the guided matches, as COLMAP estimates it:

  E      the essential matrix by RANSAC (OpenCV's five-point solver, deterministic: its generator
         has a fixed seed) on the matches' normalised coordinates, at COLMAP's threshold there:
         max_error / the mean focal length, averaged over the two cameras
  R, t   the decomposition of E (x_b = R x_a + t, |t| = 1) with the most matches in front of
         both cameras
  F      K_b^-T E K_a^-1 with the cameras as the database holds them: COLMAP's pixel convention
         (the top-left pixel's centre at (0.5, 0.5), the principal point half a pixel on from
         camera_info's), the convention of the stored keypoints
  inliers the matches within max_error of E (normalised, as above) and of F (pixels, Sampson),
         in front of both cameras

Normalised coordinates are the same in both pixel conventions (the half pixel cancels); only F
depends on it. Measured on the kitchen (37 keyframes, 137 guided pairs): of the inliers stored
before (within the band of the poses), 26% lay beyond 4 px of the stored F; the estimated
geometry keeps 95% of them within 4 px, at about 4 ms of one core a pair (of 56 ms for the
whole match_pair, measured on a loaded machine).
"""
import cv2
import numpy as np

from ..features.sift import PIXEL_CENTRE

# COLMAP 3.8's TwoViewGeometryOptions: ransac_options.max_error [px], confidence, min_num_inliers
COLMAP_MAX_ERROR_PX = 4.0
COLMAP_CONFIDENCE = 0.999
COLMAP_MIN_INLIERS = 15


class TwoViewGeometry:
    """inliers (M x 2 indices into a's and b's features), E, F (b's against a's; F in COLMAP's
    pixel convention), R, t (x_b = R x_a + t, |t| = 1)."""

    def __init__(self, inliers, E, F, R, t):
        self.inliers, self.E, self.F, self.R, self.t = inliers, E, F, R, t


def colmap_intrinsic_matrix(keyframe):
    """K of the keyframe's camera as the database holds it (COLMAP's pixel convention)."""
    fx, fy, cx, cy = keyframe.colmap_camera_params()
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def colmap_pixels(features, indices):
    """The features' coordinates as the database holds them (COLMAP's pixel convention)."""
    return features.xy[indices] + PIXEL_CENTRE


def normalised(points, k):
    """Pixel coordinates through K^-1 (the pixel convention of K's and the points' own)."""
    return cv2.undistortPoints(np.ascontiguousarray(points, np.float64).reshape(-1, 1, 2), k, None).reshape(-1, 2)


def sampson_distances(f, xa, xb):
    """Sampson distance of each correspondence (xa[i], xb[i]) to the epipolar geometry f (x_b^T f
    x_a = 0), in the units of the coordinates: COLMAP's residual (ComputeSquaredSampsonError) is
    its square."""
    ha = np.hstack([np.asarray(xa, float), np.ones((len(xa), 1))])
    hb = np.hstack([np.asarray(xb, float), np.ones((len(xb), 1))])
    fa = ha @ f.T   # f x_a: lines in b
    fb = hb @ f     # f^T x_b: lines in a
    num = np.abs(np.sum(hb * fa, axis=1))
    den = np.sqrt(fa[:, 0] ** 2 + fa[:, 1] ** 2 + fb[:, 0] ** 2 + fb[:, 1] ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / den, np.inf)


def normalised_threshold(ka, kb, max_error_px):
    """COLMAP's E threshold: max_error over each camera's mean focal length, averaged."""
    mean_focal = lambda k: (k[0, 0] + k[1, 1]) / 2.0
    return (max_error_px / mean_focal(ka) + max_error_px / mean_focal(kb)) / 2.0


def depths(na, nb, r, t):
    """The depths in a and in b of the normalised correspondences triangulated with x_b = R x_a + t
    (OpenCV's linear triangulation), NaN or inf where it gives none."""
    pa = np.hstack([np.eye(3), np.zeros((3, 1))])
    pb = np.hstack([r, np.asarray(t, float).reshape(3, 1)])
    x = cv2.triangulatePoints(pa, pb, np.ascontiguousarray(na.T), np.ascontiguousarray(nb.T))
    with np.errstate(divide="ignore", invalid="ignore"):
        pts = (x[:3] / x[3]).T
    return pts[:, 2], (pts @ r.T + np.asarray(t, float).reshape(3))[:, 2]


def in_front(na, nb, r, t):
    """Which normalised correspondences triangulate in front of both cameras (x_b = R x_a + t)."""
    za, zb = depths(na, nb, r, t)
    return np.isfinite(za) & (za > 0) & np.isfinite(zb) & (zb > 0)


def estimate(matches, fa, fb, ka, kb, max_error_px=COLMAP_MAX_ERROR_PX):
    """The geometry of matches (M x 2) between features fa, fb of keyframes ka, kb, and its
    inliers (see the module's text); None when the matches give none (fewer than five, or no
    solution)."""
    if len(matches) < 5:
        return None
    kma, kmb = colmap_intrinsic_matrix(ka), colmap_intrinsic_matrix(kb)
    xa, xb = colmap_pixels(fa, matches[:, 0]), colmap_pixels(fb, matches[:, 1])
    na, nb = normalised(xa, kma), normalised(xb, kmb)
    threshold = normalised_threshold(kma, kmb, max_error_px)
    e, _ = cv2.findEssentialMat(na, nb, np.eye(3), cv2.RANSAC, COLMAP_CONFIDENCE, threshold)
    if e is None or e.shape != (3, 3) or not np.all(np.isfinite(e)):
        return None  # degenerate, or several solutions for five matches
    f = np.linalg.inv(kmb).T @ e @ np.linalg.inv(kma)
    close = (sampson_distances(e, na, nb) <= threshold) & (sampson_distances(f, xa, xb) <= max_error_px)
    if not close.any():
        return None
    best = None
    r1, r2, t = cv2.decomposeEssentialMat(e)
    for r in (r1, r2):
        # One triangulation serves t and -t: with -t the linear triangulation's point is the
        # other's mirrored through a's centre (its system's last column changes sign), so both
        # depths change sign, exactly.
        za, zb = depths(na[close], nb[close], r, t)
        finite = np.isfinite(za) & np.isfinite(zb)
        for tt, front in ((t, finite & (za > 0) & (zb > 0)), (-t, finite & (za < 0) & (zb < 0))):
            ok = close.copy()
            ok[close] = front
            if best is None or ok.sum() > best[0].sum():
                best = (ok, r, tt.reshape(3))
    ok, r, t = best
    return TwoViewGeometry(matches[ok], e, f, r, t)
