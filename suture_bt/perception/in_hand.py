"""Needle-in-gripper transform from a needle pose estimate and the arm's reported tip pose.

``T_tip_needle = (T_world_base · measured_cp)⁻¹ · T_world_needle``. The arm's measured_cp is
computed from its measured joints, which carry the hidden joint offset (DESIGN.md §5) unless
the offset has been calibrated and compensated: the result then absorbs that error. It stays
consistent for moves that use the same uncompensated measured_cp near the same configuration,
but it is not the true grasp; compensate first when the true grasp matters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.transforms import invert

#: Where the held wire sits in the tip frame: between the blades, behind the control point.
JAW_POINT_IN_TIP = np.array([0.0, 0.0, -0.0015])


@dataclass(frozen=True)
class InHandEstimate:
    """Needle pose in the tip frame, the arc angle at the jaw and how plausible the grasp is."""

    T_tip_needle: np.ndarray
    grasp_arc_angle: float
    jaw_distance: float
    plausible: bool


def in_hand_transform(
    T_world_needle: np.ndarray, measured_cp: np.ndarray, T_world_base: np.ndarray
) -> np.ndarray:
    """Needle pose in the arm's tip frame (see module docstring about the hidden offset)."""
    for name, T in (("T_world_needle", T_world_needle), ("measured_cp", measured_cp)):
        if np.shape(T) != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"{name} must be a finite 4×4 transform")
    return invert(np.asarray(T_world_base) @ np.asarray(measured_cp)) @ np.asarray(T_world_needle)


def estimate_in_hand(
    T_world_needle: np.ndarray,
    measured_cp: np.ndarray,
    T_world_base: np.ndarray,
    model: NeedleModel | None = None,
    max_jaw_distance: float = 0.003,
) -> InHandEstimate:
    """The in-hand transform plus the grasped arc angle; implausible if the wire is far
    (> ``max_jaw_distance``) from the point between the jaws."""
    model = model or NeedleModel()
    T = in_hand_transform(T_world_needle, measured_cp, T_world_base)
    jaw_in_needle = invert(T)[:3, :3] @ JAW_POINT_IN_TIP + invert(T)[:3, 3]
    angles = np.linspace(model.tip_angle, model.base_angle, 721)
    d = np.linalg.norm(model.point_at(angles) - jaw_in_needle, axis=1)
    i = int(np.argmin(d))
    return InHandEstimate(T, float(angles[i]), float(d[i]), bool(d[i] <= max_jaw_distance))
