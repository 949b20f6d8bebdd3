"""The package's one triangulation (C++, include/view_selection/refine/triangulation.h), called
from Python: the live model (live/model.py) keeps and drops points by the same code as the
refinement's re-triangulation (refine_model), so the two cannot drift apart (issue 34).

The rules are the C++ header's: a DLT point from the normalised rays, three Gauss-Newton steps,
observations further than `max_error_px` or behind their camera dropped (the worst alone for
`drop_one_by_one` rounds, then every one beyond the limit at once), kept with two or more
observations and a triangulation angle of at least `min_angle_deg`.

The library (libview_selection_triangulation.so) is found through the library path a sourced
devel or install space sets (LD_LIBRARY_PATH), or in the build folder beside a checkout.
"""
import ctypes
import os

import numpy as np

LIBRARY = "libview_selection_triangulation.so"
ABI = 1  # VS_TRIANGULATION_ABI of triangulation_c.h

# The rule's defaults, as in triangulation.h (TriangulationRule).
MAX_ERROR_PX, MIN_ANGLE_DEG, DROP_ONE_BY_ONE = 3.0, 1.5, 6


class TriangulationError(Exception):
    pass


_lib = None


def _library():
    global _lib
    if _lib is not None:
        return _lib
    from .ros_session import DEFAULT_BUILD_DIR
    tried = []
    for candidate in (LIBRARY, os.path.join(DEFAULT_BUILD_DIR, "devel", "lib", LIBRARY)):
        try:
            lib = ctypes.CDLL(candidate)
            break
        except OSError as e:
            tried.append("%s (%s)" % (candidate, e))
    else:
        raise TriangulationError("cannot load the triangulation library: build the package and source its "
                                 "devel/setup.bash (tried %s)" % "; ".join(tried))
    lib.vs_triangulation_abi.restype = ctypes.c_int
    if lib.vs_triangulation_abi() != ABI:
        raise TriangulationError("%s has interface %d, this module needs %d: rebuild the package"
                                 % (lib._name, lib.vs_triangulation_abi(), ABI))
    d, u8, i64 = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_uint8), ctypes.POINTER(ctypes.c_int64)
    lib.vs_triangulate_tracks.argtypes = [ctypes.c_int64, i64, d, d, d, ctypes.c_double, ctypes.c_double,
                                          ctypes.c_int32, d, u8, d, u8]
    lib.vs_triangulate_tracks.restype = ctypes.c_int
    _lib = lib
    return lib


def triangulate_tracks(lengths, rotations, translations, intrinsics, xy, max_error_px=MAX_ERROR_PX,
                       min_angle_deg=MIN_ANGLE_DEG, drop_one_by_one=DROP_ONE_BY_ONE):
    """Tracks given by their lengths (n), their observations one after the other (N = sum of the
    lengths): rotations N x 3 x 3 and translations N x 3 (world to camera), intrinsics N x 4 (fx,
    fy, cx, cy), xy N x 2 pixels. Returns (points n x 3, ok n bool, mean_error n [px], inlier N
    bool)."""
    lengths = np.asarray(lengths, np.int64).reshape(-1)
    n = len(lengths)
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(lengths, out=offsets[1:])
    total = int(offsets[-1])
    poses = np.ascontiguousarray(np.concatenate([np.asarray(rotations, np.float64).reshape(total, 9),
                                                 np.asarray(translations, np.float64).reshape(total, 3)], axis=1))
    k = np.ascontiguousarray(np.asarray(intrinsics, np.float64).reshape(total, 4))
    xy = np.ascontiguousarray(np.asarray(xy, np.float64).reshape(total, 2))
    points = np.zeros((n, 3), np.float64)
    ok = np.zeros(n, np.uint8)
    mean_error = np.zeros(n, np.float64)
    inlier = np.zeros(total, np.uint8)
    ptr = lambda a, t: a.ctypes.data_as(ctypes.POINTER(t))
    status = _library().vs_triangulate_tracks(
        n, ptr(offsets, ctypes.c_int64), ptr(poses, ctypes.c_double), ptr(k, ctypes.c_double),
        ptr(xy, ctypes.c_double), float(max_error_px), float(min_angle_deg), int(drop_one_by_one),
        ptr(points, ctypes.c_double), ptr(ok, ctypes.c_uint8), ptr(mean_error, ctypes.c_double),
        ptr(inlier, ctypes.c_uint8))
    if status != 0:
        raise TriangulationError("vs_triangulate_tracks refused its arguments (max_error_px %r, min_angle_deg %r, "
                                 "drop_one_by_one %r)" % (max_error_px, min_angle_deg, drop_one_by_one))
    return points, ok.astype(bool), mean_error, inlier.astype(bool)
