"""Shared synthetic-scene helpers for the perception tests (no simulator needed)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from suture_bt.interfaces import CameraModel, StereoCameraModel
from suture_bt.transforms import make_transform, pose_to_transform


def stereo(width: int, height: int) -> StereoCameraModel:
    """The SRC endoscope geometry (DESIGN.md §5) built from the core camera model."""
    T_cf = pose_to_transform((0.0, 0.0963, 0.1671), (0.6981, 0.0, -np.pi))
    eyes = [
        CameraModel.from_fov(
            width,
            height,
            1.2,
            T_cf @ make_transform(np.diag([1.0, -1.0, -1.0]), (s * 0.002, 0, -0.05)),
        )
        for s in (-1.0, 1.0)
    ]
    return StereoCameraModel(*eyes)


def random_needle_pose(
    rng: np.random.Generator, zmin: float = 0.08, zmax: float = 0.2
) -> np.ndarray:
    """A needle pose in the left camera frame, in view, 80-200 mm away."""
    z = rng.uniform(zmin, zmax)
    pos = np.array([rng.uniform(-0.25, 0.25) * z, rng.uniform(-0.15, 0.15) * z, z])
    return make_transform(Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix(), pos)


def pose_errors(Ta: np.ndarray, Tb: np.ndarray) -> tuple[float, float]:
    """(position error mm, geodesic angle error deg)."""
    pos = float(np.linalg.norm(Ta[:3, 3] - Tb[:3, 3]) * 1e3)
    ang = float(np.degrees(Rotation.from_matrix(Ta[:3, :3].T @ Tb[:3, :3]).magnitude()))
    return pos, ang
