import numpy as np
import pytest

from view_selection import geometry


def test_quaternion_round_trip():
    for q in [(1, 0, 0, 0), (0, 1, 0, 0), (0.5, 0.5, 0.5, 0.5), (0.1, -0.7, 0.2, 0.68), (-0.3, 0.1, 0.9, 0.2)]:
        q = np.array(q) / np.linalg.norm(q)
        back = geometry.quaternion_of(geometry.rotation_of(q))
        assert np.allclose(back, q if q[0] >= 0 else -q)


def test_world_to_camera_inverts_the_camera_pose():
    c, q = (1.0, -2.0, 0.5), (0.9, 0.1, 0.3, -0.2)
    qv, tv = geometry.world_to_camera(c, q)
    r = geometry.rotation_of(qv)
    assert np.allclose(r @ np.array(c) + tv, 0)  # the centre maps to the camera's origin
    assert np.allclose(geometry.centre_of(qv, tv), c)
    c2, q2 = geometry.camera_to_world(qv, tv)
    assert np.allclose(c2, c) and geometry.rotation_angle_deg(q2, q) == pytest.approx(0, abs=1e-6)


def test_not_a_rotation_is_refused():
    with pytest.raises(ValueError):
        geometry.rotation_of((0, 0, 0, 0))
    with pytest.raises(ValueError):
        geometry.rotation_of((float("nan"), 0, 0, 1))
