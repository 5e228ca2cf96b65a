"""Checks for values that cross an interface: joint vectors and poses, with a clear reason."""

from __future__ import annotations

import numpy as np

from suture_bt.kinematics.psm import NUM_JOINTS


def as_joint_vector(q, what: str) -> np.ndarray:
    """``q`` as a float vector of 6 finite joint values, else ValueError naming ``what``."""
    v = np.asarray(q, dtype=float).reshape(-1)
    if v.shape != (NUM_JOINTS,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{what}: expected {NUM_JOINTS} finite joint values, got {q!r}")
    return v


def as_pose(T, what: str) -> np.ndarray:
    """``T`` as a finite 4×4 rigid transform, else ValueError naming ``what``."""
    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise ValueError(f"{what}: expected a finite 4×4 pose, got shape {M.shape}")
    if not np.allclose(M[:3, :3] @ M[:3, :3].T, np.eye(3), atol=1e-6):
        raise ValueError(f"{what}: the rotation part is not orthonormal")
    return M
