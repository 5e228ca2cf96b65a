"""Closed-form PSM inverse kinematics (DESIGN.md §5), exact to machine precision.

The wrist-yaw point is the tip backed off along tip z; the wrist-pitch point lies
L_pitch2yaw from it in the tip y-z plane, on the shaft line through the RCM, which fixes
q1-q3. The wrist axes then give q4-q6; the pitch-axis sign picks one of two wrist branches.
"""

from __future__ import annotations

import numpy as np

from suture_bt.kinematics.psm import (
    JOINT_LIMITS,
    L_PITCH2YAW,
    L_TOOL2RCM,
    L_YAW2CTRLPNT,
    frame_transforms,
    limit_violations,
)

_LOWER, _UPPER = JOINT_LIMITS[:, 0].copy(), JOINT_LIMITS[:, 1].copy()


class UnreachablePoseError(ValueError):
    """The requested tip pose has no IK solution inside the joint limits; ``reason`` says why."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


def _rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


_RX_MINUS_HALF_PI = _rot_x(-np.pi / 2)


def _wrist_from_pitch_axis(q123: np.ndarray, z5: np.ndarray, x5: np.ndarray, R7: np.ndarray):
    """q4, q5, q6 given the wrist-pitch axis z5 and frame-5 x axis x5 (base frame)."""
    R3 = frame_transforms(np.r_[q123, 0, 0, 0], upto=3)[-1][:3, :3]
    z5_3 = R3.T @ z5  # pitch axis = frame-4 y axis = (-sin q4, cos q4, 0) in frame 3
    q4 = np.arctan2(-z5_3[0], z5_3[1])
    R4 = R3 @ _rot_z(q4)  # α4 = 0, θ4 = q4
    x5_4 = R4.T @ x5  # = (cos a, 0, -sin a), a = q5 - π/2
    q5 = np.arctan2(-x5_4[2], x5_4[0]) + np.pi / 2
    R5 = R4 @ _RX_MINUS_HALF_PI @ _rot_z(q5 - np.pi / 2)
    x6 = -R7[:, 1]  # tip y = -(frame-6 x)
    x6_5 = R5.T @ x6  # = (cos b, 0, -sin b), b = q6 - π/2
    q6 = np.arctan2(-x6_5[2], x6_5[0]) + np.pi / 2
    return np.array([_wrap(q4), _wrap(q5), _wrap(q6)])


def ik_branches(T_tip: np.ndarray) -> list[np.ndarray]:
    """Both wrist-branch solutions (ignoring joint limits) for a tip pose in the base frame."""
    T_tip = np.asarray(T_tip, dtype=float)
    R7, p7 = T_tip[:3, :3], T_tip[:3, 3]
    yaw_point = p7 - L_YAW2CTRLPNT * R7[:, 2]
    # Direction from the yaw point toward the RCM, projected into the tip y-z plane.
    to_rcm = -yaw_point
    in_plane = to_rcm - np.dot(to_rcm, R7[:, 0]) * R7[:, 0]
    norm = np.linalg.norm(in_plane)
    if norm < 1e-12:
        raise UnreachablePoseError("tip x axis points at the RCM: wrist pitch point is undefined")
    n = in_plane / norm
    # The pitch point lies on the RCM side of the yaw point (the usual wrist) or beyond it
    # (the wrist folded back): the two branches of the closed form.
    return [_solve_for_pitch_direction(yaw_point, s * n, R7) for s in (1.0, -1.0)]


def _solve_for_pitch_direction(yaw_point: np.ndarray, n: np.ndarray, R7: np.ndarray):
    """Full joint vector when the pitch point is ``yaw_point + L_pitch2yaw · n``."""
    pitch_point = yaw_point + L_PITCH2YAW * n
    x, y, z = pitch_point
    q1 = np.arctan2(x, -z)
    q2 = -np.arctan2(y, np.hypot(x, z))
    q3 = np.linalg.norm(pitch_point) + L_TOOL2RCM
    q123 = np.array([q1, q2, q3])
    x5 = -n  # frame-6 origin = frame-5 origin + L_pitch2yaw · x5
    y5 = -R7[:, 0]  # frame-6 z (yaw axis) = frame-5 y = -tip x
    z5 = np.cross(x5, y5)
    return np.r_[q123, _wrist_from_pitch_axis(q123, z5, x5, R7)]


def inverse_kinematics(T_tip: np.ndarray, q_current=None) -> np.ndarray:
    """Joint vector reaching tip pose ``T_tip`` (base frame), inside the limits.

    Of the two wrist branches, returns the one inside the limits nearest ``q_current``
    (weighted joint distance). Raises :class:`UnreachablePoseError` with the violated
    joint(s) when neither is inside the limits.
    """
    branches = ik_branches(T_tip)
    feasible = [q for q in branches if in_limits(q)]
    if not feasible:
        reasons = "; ".join(limit_violations(branches[0]))
        raise UnreachablePoseError(f"no IK solution inside the joint limits: {reasons}")
    if len(feasible) == 1 or q_current is None:
        if q_current is None:
            # Without a reference, prefer the branch with the smaller wrist pitch.
            feasible.sort(key=lambda q: abs(q[4]))
        return feasible[0]
    qc = np.asarray(q_current, dtype=float)
    return min(feasible, key=lambda q: float(np.sum(np.abs(q - qc))))


def in_limits(q, tol: float = 1e-9) -> bool:
    """True when every joint of q is inside its limit (within ``tol``)."""
    q = np.asarray(q)
    return bool(np.all(q >= _LOWER - tol) and np.all(q <= _UPPER + tol))
