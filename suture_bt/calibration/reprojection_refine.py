"""Refine a joint-offset estimate by fitting the arm's projected jaw keypoints to the detected ones.

The seed's MLP maps keypoint pixels to Δq̂ in one step; near the edges of the offset box it
trained on it shrinks toward the middle (at the corner (5°, 5°, 5 mm): 0.25°, 0.25°, 0.33 mm
short, its keypoint residual 11.7σ where the detections fit to 0.5σ). Levenberg-Marquardt
steps of the keypoint reprojection error over the three offsets, from the MLP's answer, take
the estimate to the arm pose the detections show: the kinematic model and the camera only,
as in the residual check that follows.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from suture_bt.calibration.jaw_keypoints import project_keypoints

#: Parameter scales (rad, rad, m) of the least-squares steps: a tenth of a degree or mm.
SCALE = np.array([np.deg2rad(0.1), np.deg2rad(0.1), 1e-4])


def refine_offset(
    start: np.ndarray,
    keypoints: np.ndarray,
    q_meas: np.ndarray,
    jaw: float,
    T_world_base: np.ndarray,
    cam,
    sigma_px: np.ndarray | float,
) -> np.ndarray:
    """Δq (3, SI) minimising the keypoint reprojection error (each keypoint's pixel error over
    its ``sigma_px``, at the camera's resolution), starting from ``start``."""
    q_meas = np.asarray(q_meas, dtype=float)
    kp = np.asarray(keypoints, dtype=float)
    sigma = np.broadcast_to(np.asarray(sigma_px, dtype=float).reshape(-1, 1), kp.shape)

    def residuals(offset: np.ndarray) -> np.ndarray:
        q = q_meas.copy()
        q[:3] += offset
        return ((project_keypoints(q, jaw, T_world_base, cam)[0] - kp) / sigma).ravel()

    sol = least_squares(residuals, np.asarray(start, dtype=float), x_scale=SCALE, method="lm")
    return sol.x if np.all(np.isfinite(sol.x)) else np.asarray(start, dtype=float)
