"""Seeded drift added to exact poses: what a SLAM front end without loop closure gives.

The drift is a random walk, step by step along the trajectory in its order (frame or photo
order). With the true step from pose i-1 to pose i (centre step d_i, rotation step),

  - the drifted rotation is D_i R_i, where D_i = exp(w_i) D_{i-1} and w_i is a rotation about a
    uniformly random axis by `rotation_deg` degrees (fixed size, random direction);
  - the drifted centre is c'_i = c'_{i-1} + D_{i-1} d_i + e_i, where e_i points in a uniformly
    random direction with length `translation_ratio` |d_i|.

The first pose is exact (a SLAM system starts where it is). Since the accumulated rotation D
turns every later step, the position error grows faster than the translation noise alone: with
the defaults (2% of each step, 0.3 degrees a step, the figures of issue 29's held-out sets) the
end of a 48-step DTU ring lands about 2% of the distance travelled from the truth (measured per
set in docs/live.md, "Refinement").
"""
import math

import numpy as np

from .. import geometry


def _random_unit(rng):
    v = rng.normal(size=3)
    n = np.linalg.norm(v)
    return v / n if n > 0 else np.array([1.0, 0.0, 0.0])


def _axis_angle(axis, angle):
    axis = np.asarray(axis, float)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def add_drift(poses, translation_ratio=0.02, rotation_deg=0.3, seed=0):
    """poses: [(centre (3,), camera-to-world quaternion (w, x, y, z))] in trajectory order.
    Returns the drifted poses in the same form."""
    rng = np.random.default_rng(seed)
    out = []
    drift = np.eye(3)
    previous_true = previous_drifted = None
    for centre, q in poses:
        c = np.asarray(centre, float)
        r = geometry.rotation_of(q)
        if previous_true is None:
            drifted_centre = c.copy()
        else:
            step = c - previous_true
            noise = translation_ratio * np.linalg.norm(step) * _random_unit(rng)
            drifted_centre = previous_drifted + drift @ step + noise
            drift = _axis_angle(_random_unit(rng), math.radians(rotation_deg)) @ drift
        out.append((tuple(float(v) for v in drifted_centre), geometry.quaternion_of(drift @ r)))
        previous_true, previous_drifted = c, drifted_centre
    return out


def path_length(centres):
    c = np.asarray(centres, float).reshape(-1, 3)
    return float(np.linalg.norm(np.diff(c, axis=0), axis=1).sum()) if len(c) > 1 else 0.0


# -- TUM folders -----------------------------------------------------------------------------
def read_groundtruth(path):
    """[(stamp, centre, (w, x, y, z))] of a TUM groundtruth.txt (tx ty tz qx qy qz qw)."""
    rows = []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts or parts[0].startswith("#"):
                continue
            if len(parts) < 8:
                raise ValueError("%s: a pose line needs 8 values: %r" % (path, line.strip()))
            v = [float(x) for x in parts[:8]]
            rows.append((v[0], tuple(v[1:4]), (v[7], v[4], v[5], v[6])))
    return rows


def write_groundtruth(path, rows, comment="ground truth trajectory"):
    with open(path + ".tmp", "w") as f:
        f.write("# %s\n# timestamp tx ty tz qx qy qz qw\n" % comment)
        for stamp, c, (w, x, y, z) in rows:
            f.write("%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n" % (stamp, c[0], c[1], c[2], x, y, z, w))
    import os
    os.replace(path + ".tmp", path)


def drifted_tum_folder(dataset, out, translation_ratio=0.02, rotation_deg=0.3, seed=0):
    """A copy of the TUM folder `dataset` in `out` whose groundtruth.txt holds drifted poses
    (every other file linked). The exact poses stay in out/groundtruth_exact.txt. Returns
    (exact rows, drifted rows)."""
    import os
    os.makedirs(out, exist_ok=True)
    for name in os.listdir(dataset):
        if name == "groundtruth.txt":
            continue
        target = os.path.join(out, name)
        if not os.path.lexists(target):
            os.symlink(os.path.abspath(os.path.join(dataset, name)), target)
    exact = read_groundtruth(os.path.join(dataset, "groundtruth.txt"))
    drifted = add_drift([(c, q) for _, c, q in exact], translation_ratio, rotation_deg, seed)
    rows = [(s, c, q) for (s, _, _), (c, q) in zip(exact, drifted)]
    write_groundtruth(os.path.join(out, "groundtruth_exact.txt"), exact, "exact poses of the source")
    write_groundtruth(os.path.join(out, "groundtruth.txt"), rows,
                      "drifted: random walk, %.3g of each step, %.3g deg a step, seed %d"
                      % (translation_ratio, rotation_deg, seed))
    return exact, rows
