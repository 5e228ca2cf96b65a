"""Homogeneous-transform helpers (4×4 numpy arrays) built on scipy's Rotation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def make_transform(rotation: np.ndarray | None = None, position=None) -> np.ndarray:
    """A 4×4 transform from a 3×3 rotation and a position (defaults: identity, origin)."""
    T = np.eye(4)
    if rotation is not None:
        T[:3, :3] = rotation
    if position is not None:
        T[:3, 3] = position
    return T


def rpy_to_matrix(rpy) -> np.ndarray:
    """Rotation Rz(yaw)·Ry(pitch)·Rx(roll) for rpy = (roll, pitch, yaw), the SRC/KDL convention."""
    return Rotation.from_euler("ZYX", [rpy[2], rpy[1], rpy[0]]).as_matrix()


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix`: (roll, pitch, yaw)."""
    yaw, pitch, roll = Rotation.from_matrix(R).as_euler("ZYX")
    return np.array([roll, pitch, yaw])


def pose_to_transform(position, rpy) -> np.ndarray:
    """A 4×4 transform from a position and (roll, pitch, yaw)."""
    return make_transform(rpy_to_matrix(rpy), position)


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform without a general matrix inverse."""
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


def quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) of a rotation matrix; robust near 180° (scipy)."""
    return Rotation.from_matrix(R).as_quat()


def matrix_from_quat_xyzw(q) -> np.ndarray:
    """Rotation matrix from a quaternion (x, y, z, w)."""
    return Rotation.from_quat(q).as_matrix()


def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Geodesic angle (rad) between two rotations."""
    return float(Rotation.from_matrix(Ra.T @ Rb).magnitude())
