"""Geometric baseline for the joint offset: keypoints → PnP → inverse kinematics − measured joints.

Why: a comparison for the learned regressor that uses no training at all. With joints 4-6 and
the jaw read exactly, the 4 keypoints are a known rigid object in the shaft frame (DH frame 3);
OpenCV's PnP (iterative, started from the measured joints) gives that frame's pose in the
camera, hence the wrist-pitch point in the arm's base frame, whose closed-form inverse (the
q1-q3 part of the PSM IK, DESIGN.md §5) gives the true joints 1-3; Δq̂ = those − measured.
PnP estimates 6 degrees of freedom from 8 numbers for a 3-DoF problem, so it is noisier.
"""

from __future__ import annotations

import cv2
import numpy as np

from suture_bt.calibration.jaw_keypoints import keypoints_in_base
from suture_bt.interfaces import CameraModel
from suture_bt.kinematics import frame_transforms
from suture_bt.kinematics.psm import L_TOOL, L_TOOL2RCM
from suture_bt.transforms import invert


def shaft_frame(q) -> np.ndarray:
    """Base transform of DH frame 3 (the shaft before its roll) for joints q."""
    return frame_transforms(q, upto=3)[-1]


def joints123_from_pitch_point(p_base: np.ndarray) -> np.ndarray:
    """q1, q2, q3 that put the wrist-pitch point at ``p_base`` (closed form, DESIGN.md §5)."""
    x, y, z = p_base
    return np.array(
        [np.arctan2(x, -z), -np.arctan2(y, np.hypot(x, z)), np.linalg.norm(p_base) + L_TOOL2RCM]
    )


def pnp_offset(
    pixels: np.ndarray, q_meas, jaw: float, T_world_base: np.ndarray, cam: CameraModel
) -> np.ndarray:
    """Δq̂ (3, SI) from 4 keypoint pixels (4×2) by PnP on the shaft-frame keypoint model."""
    q_meas = np.asarray(q_meas, dtype=float)
    T3 = shaft_frame(q_meas)
    model_3 = (keypoints_in_base(q_meas, jaw)[0] - T3[:3, 3]) @ T3[:3, :3]  # in frame 3
    T_cam_3 = cam.T_cam_world @ T_world_base @ T3  # initial guess: the measured joints
    rvec, _ = cv2.Rodrigues(T_cam_3[:3, :3])
    tvec = T_cam_3[:3, 3].reshape(3, 1)
    ok, rvec, tvec = cv2.solvePnP(
        model_3.astype(np.float64),
        np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2),
        cam.K,
        None,
        rvec,
        tvec,
        useExtrinsicGuess=True,
        flags=cv2.SOLVEPNP_ITERATIVE,
    )
    if not ok:
        raise ValueError("PnP did not converge")
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    T_base_3 = invert(T_world_base) @ cam.T_world_cam @ T
    pitch_point = T_base_3[:3, :3] @ np.array([0.0, 0.0, L_TOOL]) + T_base_3[:3, 3]
    return joints123_from_pitch_point(pitch_point) - q_meas[:3]
