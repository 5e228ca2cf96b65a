"""Transform helpers: the SRC RPY convention, rigid inverse, quaternions near 180°."""

import numpy as np

from suture_bt.transforms import (
    invert,
    make_transform,
    matrix_from_quat_xyzw,
    matrix_to_rpy,
    pose_to_transform,
    quat_xyzw,
    rotation_angle,
    rpy_to_matrix,
)


def _rx(a):
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def _ry(a):
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def _rz(a):
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_rpy_is_rz_ry_rx():
    r, p, y = 0.6981, -0.5236, -np.pi
    np.testing.assert_allclose(rpy_to_matrix((r, p, y)), _rz(y) @ _ry(p) @ _rx(r), atol=1e-12)
    np.testing.assert_allclose(
        rpy_to_matrix(matrix_to_rpy(_rz(0.3) @ _rx(0.2))), _rz(0.3) @ _rx(0.2)
    )


def test_invert_is_the_rigid_inverse():
    T = pose_to_transform((0.1, 0.2, 0.3), (0.4, -0.5, 0.6))
    np.testing.assert_allclose(invert(T) @ T, np.eye(4), atol=1e-12)
    assert make_transform()[3, 3] == 1.0


def test_quaternion_round_trip_near_180_degrees():
    R = _rz(np.pi - 1e-9) @ _rx(1e-9)
    np.testing.assert_allclose(matrix_from_quat_xyzw(quat_xyzw(R)), R, atol=1e-9)
    assert abs(rotation_angle(np.eye(3), R) - np.pi) < 1e-6
