"""The 4 calibration keypoints on the PSM wrist and jaw, and their 3-D positions for joint vectors.

Why these points: they are sharp, visible corners of the instrument's last links (two corners
of the wrist clevis and the two jaw tips), not collinear, and they span the wrist so that
their image encodes its position and orientation — which, with joints 4-6 and the jaw read
exactly from the encoders, fixes the biased joints 1-3 (DESIGN.md §5). (Points on the joint
axes inside the clevis were tried first: a CNN found them only to 2.5-5.6 px, the corners and
tips to about 0.6 px.)

Definitions (modified-DH frames of ``suture_bt.kinematics``; geometry of the sim's body,
``suture_bt.sim.psm_body``):

0. ``clevis_corner_a`` / 1. ``clevis_corner_b``: the clevis box (frame 5, x ∈ [−2, 11] mm,
   y ∈ ±2.2 mm, z ∈ ±3 mm) corners at x = 11 mm (the jaw end), y = −2.2 mm, z = −3 / +3 mm;
   both face the endoscope at the calibration poses of both arms;
2. ``jaw_tip_a`` / 3. ``jaw_tip_b``: the centres of the two jaw blades' end faces. Blade a
   turns by +jaw/2 and blade b by −jaw/2 about the yaw axis (frame 6 z); in its own turned
   frame each blade runs along +y to ``JAW_TIP_LENGTH`` and sits ``JAW_HALF_THICKNESS`` to the
   −x (a) or +x (b) side of the frame-6 y-z plane (JAW_LENGTH, JAW_THICKNESS of the body).

Everything is vectorised over a batch of joint vectors (N×6) for data generation.
"""

from __future__ import annotations

import numpy as np

from suture_bt.kinematics.psm import L_PITCH2YAW, L_RCC, L_TOOL

KEYPOINT_NAMES = ("clevis_corner_a", "clevis_corner_b", "jaw_tip_a", "jaw_tip_b")
NUM_KEYPOINTS = len(KEYPOINT_NAMES)
#: Jaw blade length from the wrist-yaw axis and half its thickness (m), as the sim's blades.
JAW_TIP_LENGTH = 0.0125
JAW_HALF_THICKNESS = 0.0006
#: The two clevis corners in frame 5 (m).
CLEVIS_CORNERS = np.array([[0.011, -0.0022, -0.003], [0.011, -0.0022, 0.003]])


def _dh_batch(alpha: float, a: float, theta: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Batch of modified-DH transforms Rx(α)·Tx(a)·Rz(θ)·Tz(d), shape N×4×4."""
    n = theta.shape[0]
    ca, sa = np.cos(alpha), np.sin(alpha)
    ct, st = np.cos(theta), np.sin(theta)
    T = np.zeros((n, 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 0, 3] = ct, -st, a
    T[:, 1, 0], T[:, 1, 1], T[:, 1, 2], T[:, 1, 3] = st * ca, ct * ca, -sa, -sa * d
    T[:, 2, 0], T[:, 2, 1], T[:, 2, 2], T[:, 2, 3] = st * sa, ct * sa, ca, ca * d
    T[:, 3, 3] = 1.0
    return T


def wrist_frames(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Base-frame transforms of frames 5 and 6 (N×4×4 each) for joint vectors q (N×6)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[1] < 6:
        raise ValueError(f"joint vectors need 6 values, got {q.shape[1]}")
    h = np.pi / 2
    zero = np.zeros(q.shape[0])
    T = _dh_batch(h, 0.0, q[:, 0] + h, zero)
    T = T @ _dh_batch(-h, 0.0, q[:, 1] - h, zero)
    T = T @ _dh_batch(h, 0.0, zero, q[:, 2] - L_RCC)
    T = T @ _dh_batch(0.0, 0.0, q[:, 3], zero + L_TOOL)
    T5 = T @ _dh_batch(-h, 0.0, q[:, 4] - h, zero)
    T6 = T5 @ _dh_batch(-h, L_PITCH2YAW, q[:, 5] - h, zero)
    return T5, T6


def keypoints_in_frame6(jaw: np.ndarray) -> np.ndarray:
    """The keypoints in frame 6 (N×4×3) for jaw angles (N,) in rad (0, 1: unused, zero)."""
    jaw = np.atleast_1d(np.asarray(jaw, dtype=float))
    pts = np.zeros((jaw.shape[0], NUM_KEYPOINTS, 3))
    for k, side in ((2, 1.0), (3, -1.0)):
        a = side * jaw / 2.0  # blade a turns +jaw/2, blade b −jaw/2 about frame-6 z
        x, y = -side * JAW_HALF_THICKNESS, JAW_TIP_LENGTH
        pts[:, k] = np.stack(
            [np.cos(a) * x - np.sin(a) * y, np.sin(a) * x + np.cos(a) * y, 0 * a], 1
        )
    return pts


def keypoints_in_base(q, jaw) -> np.ndarray:
    """Keypoints (N×4×3) in the base (RCM) frame for joints q (N×6 or 6), jaw (N or scalar)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    jaw = np.broadcast_to(np.asarray(jaw, dtype=float), (q.shape[0],))
    T5, T6 = wrist_frames(q)
    local = keypoints_in_frame6(jaw)
    out = np.einsum("nij,nkj->nki", T6[:, :3, :3], local) + T6[:, None, :3, 3]
    out[:, :2] = np.einsum("nij,kj->nki", T5[:, :3, :3], CLEVIS_CORNERS) + T5[:, None, :3, 3]
    return out


def keypoints_in_world(q, jaw, T_world_base: np.ndarray) -> np.ndarray:
    """Keypoints (N×4×3) in the world frame."""
    pb = keypoints_in_base(q, jaw)
    return pb @ T_world_base[:3, :3].T + T_world_base[:3, 3]


def project_keypoints(q, jaw, T_world_base: np.ndarray, camera) -> np.ndarray:
    """Pixel coordinates (N×4×2) of the keypoints in ``camera`` (a CameraModel)."""
    pw = keypoints_in_world(q, jaw, T_world_base)
    n = pw.shape[0]
    return camera.project(pw.reshape(-1, 3)).reshape(n, NUM_KEYPOINTS, 2)


def keypoint_depths(q, jaw, T_world_base: np.ndarray, camera) -> np.ndarray:
    """Depth (camera z, m) of each keypoint, N×4; positive in front of the camera."""
    pw = keypoints_in_world(q, jaw, T_world_base)
    n = pw.shape[0]
    return camera.to_camera(pw.reshape(-1, 3))[:, 2].reshape(n, NUM_KEYPOINTS)
