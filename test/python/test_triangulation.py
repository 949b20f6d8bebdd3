"""The C++ triangulation called from Python (view_selection.triangulation): the tracks and their
observations reach it in order, and what comes back lands on the right track and observation.
The rules themselves are tested once, in C++ (test/refine/test_triangulation.cpp)."""
import numpy as np
import pytest

from view_selection import triangulation

K = np.array([500.0, 500.0, 320.0, 240.0])


def observe(centre, x, offset=(0.0, 0.0)):
    p = np.asarray(x, float) - np.asarray(centre, float)  # R = I, t = -centre
    return np.array([K[0] * p[0] / p[2] + K[2], K[1] * p[1] / p[2] + K[3]]) + offset


def test_two_tracks_in_one_call_each_get_their_point_and_inliers():
    x1, x2 = np.array([0.2, -0.1, 2.0]), np.array([-0.3, 0.1, 4.0])
    centres = [(0.1 * i, 0.0, 0.0) for i in range(4)] + [(0.0, 0.2 * i, 0.0) for i in range(3)]
    xy = [observe(c, x1) for c in centres[:4]] + [observe(centres[4], x2), observe(centres[5], x2, (30.0, 0.0)),
                                                  observe(centres[6], x2)]
    n = len(centres)
    points, ok, error, inlier = triangulation.triangulate_tracks(
        [4, 3], np.repeat(np.eye(3)[None], n, 0), -np.array(centres), np.tile(K, (n, 1)), np.array(xy))
    assert ok.tolist() == [True, True]
    assert np.allclose(points[0], x1, atol=1e-8) and np.allclose(points[1], x2, atol=1e-8)
    assert inlier.tolist() == [True, True, True, True, True, False, True]
    assert error[0] < 1e-6 and error[1] < 1e-6


def test_a_track_with_no_point_and_an_empty_call():
    x = np.array([0.0, 0.0, 2.0])
    xy = [observe((0, 0, 0), x), observe((0.1, 0, 0), x, (0.0, 40.0))]
    _, ok, _, inlier = triangulation.triangulate_tracks([2], np.repeat(np.eye(3)[None], 2, 0),
                                                        -np.array([(0, 0, 0), (0.1, 0, 0)], float),
                                                        np.tile(K, (2, 1)), np.array(xy))
    assert ok.tolist() == [False] and not inlier.any()
    points, ok, _, inlier = triangulation.triangulate_tracks([], np.zeros((0, 3, 3)), np.zeros((0, 3)),
                                                             np.zeros((0, 4)), np.zeros((0, 2)))
    assert points.shape == (0, 3) and ok.shape == (0,) and inlier.shape == (0,)


def test_arguments_the_library_refuses_raise():
    with pytest.raises(triangulation.TriangulationError):
        triangulation.triangulate_tracks([2], np.repeat(np.eye(3)[None], 2, 0), np.zeros((2, 3)),
                                         np.tile(K, (2, 1)), np.zeros((2, 2)), max_error_px=0.0)
