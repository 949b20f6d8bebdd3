"""Absolute trajectory error: camera centres aligned to a reference by a similarity (Umeyama,
1991: scale, rotation, translation), then the RMSE of the distances that remain. The same
definition as the C++ tool evaluate_trajectory (eval/trajectory_alignment), which works on COLMAP
models and TUM folders; this one works on lists of centres, for the Python tools."""
import numpy as np


def umeyama(source, target, with_scale=True):
    """(scale, R, t) minimising sum |target_i - (scale R source_i + t)|^2 over 3-vectors matched
    by index. Raises ValueError for fewer than 3 points or a degenerate (collinear) set."""
    x = np.asarray(source, float).reshape(-1, 3).T
    y = np.asarray(target, float).reshape(-1, 3).T
    if x.shape[1] != y.shape[1]:
        raise ValueError("%d source points for %d target points" % (x.shape[1], y.shape[1]))
    if x.shape[1] < 3:
        raise ValueError("an alignment needs at least 3 points, not %d" % x.shape[1])
    mx, my = x.mean(axis=1, keepdims=True), y.mean(axis=1, keepdims=True)
    xc, yc = x - mx, y - my
    n = x.shape[1]
    cov = yc @ xc.T / n
    u, d, vt = np.linalg.svd(cov)
    if d[1] <= 1e-12 * max(d[0], 1e-300):
        raise ValueError("the points are collinear: no unique rotation")
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1
    r = u @ s @ vt
    var = (xc ** 2).sum() / n
    scale = float(np.trace(np.diag(d) @ s) / var) if (with_scale and var > 0) else 1.0
    t = my - scale * r @ mx
    return scale, r, t.reshape(3)


def aligned(source, target, with_scale=True):
    """`source` after the alignment to `target` (N x 3)."""
    scale, r, t = umeyama(source, target, with_scale)
    return (scale * (r @ np.asarray(source, float).reshape(-1, 3).T)).T + t


def ate_errors(estimated, reference, with_scale=True):
    """Per point distance after the alignment (N,)."""
    a = aligned(estimated, reference, with_scale)
    return np.linalg.norm(a - np.asarray(reference, float).reshape(-1, 3), axis=1)


def ate_rmse(estimated, reference, with_scale=True):
    """RMSE of camera centres after a Sim(3) alignment of `estimated` to `reference`; NaN for
    fewer than 3 centres or a degenerate set (an ATE that cannot be measured, not 0)."""
    try:
        e = ate_errors(estimated, reference, with_scale)
    except ValueError:
        return float("nan")
    return float(np.sqrt((e ** 2).mean()))
