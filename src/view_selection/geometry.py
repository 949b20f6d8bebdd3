"""Rotations and camera poses in COLMAP's and the node's conventions.

The node's keyframes carry a camera-to-world pose: the camera centre in the world and the
rotation of the optical frame (z forward, x right, y down) as a quaternion. COLMAP's images carry
the world-to-camera transform: x_cam = R x_world + t, with R as (qw, qx, qy, qz).
Quaternions here are (w, x, y, z) tuples unless a name says otherwise.
"""
import math

import numpy as np


def rotation_of(q):
    """3x3 rotation matrix (numpy) of a quaternion (w, x, y, z), normalised first."""
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not n > 0 or not math.isfinite(n):
        raise ValueError("not a rotation quaternion: %r" % (tuple(q),))
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def quaternion_of(r):
    """(w, x, y, z) of a 3x3 rotation, with w >= 0."""
    r = np.asarray(r, float)
    t = r[0, 0] + r[1, 1] + r[2, 2]
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = (0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s)
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = ((r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s)
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = ((r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s)
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = ((r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s)
    n = math.sqrt(sum(v * v for v in q))
    q = tuple(float(v) / n for v in q)
    return q if q[0] >= 0 else tuple(-v for v in q)


def world_to_camera(position, orientation):
    """COLMAP's image pose (qvec, tvec) from a camera-to-world pose (centre, (w, x, y, z))."""
    r = rotation_of(orientation).T  # world -> camera
    t = -r @ np.asarray(position, float)
    return quaternion_of(r), tuple(float(v) for v in t)


def centre_of(qvec, tvec):
    """The camera centre in the world of a COLMAP image pose: -R^T t."""
    r = rotation_of(qvec)
    return tuple(float(v) for v in -r.T @ np.asarray(tvec, float))


def camera_to_world(qvec, tvec):
    """The node's (centre, (w, x, y, z) camera-to-world) of a COLMAP image pose."""
    w, x, y, z = qvec
    q = (w, -x, -y, -z)
    return centre_of(qvec, tvec), (q if q[0] >= 0 else tuple(-v for v in q))


def rotation_angle_deg(qa, qb):
    """The angle of the rotation between two quaternions, in degrees."""
    ra, rb = rotation_of(qa), rotation_of(qb)
    c = (np.trace(ra.T @ rb) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))
