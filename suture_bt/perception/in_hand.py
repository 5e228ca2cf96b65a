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
from suture_bt.kinematics.psm import L_YAW2CTRLPNT
from suture_bt.transforms import invert

#: Where the held wire sits in the tip frame: between the blades, behind the control point.
JAW_POINT_IN_TIP = np.array([0.0, 0.0, -0.0015])
#: The stretch of the tip z axis between the blades that can hold the wire (m): from 3 mm past
#: the wrist-yaw pivot to the blade end (large needle driver). A wire held anywhere along it
#: is held: a grasp that closed 2.5 mm deeper than the pinch point is not "another needle".
BLADE_Z_RANGE = (-L_YAW2CTRLPNT + 0.003, 0.0019)


#: Tip moves (m, rad) within which an uncalibrated arm's in-hand estimate still holds: the
#: hidden offset it absorbed changes with the configuration, so it is only valid where it was
#: measured (a few tenths of a millimetre of tip error per millimetre moved is typical).
SAME_POSE_POSITION = 0.001
SAME_POSE_ANGLE = np.deg2rad(1.0)


@dataclass(frozen=True)
class InHandEstimate:
    """Needle pose in the tip frame, the arc angle at the jaw and how plausible the grasp is.

    What it absorbs: the transform is taken against the arm's *reported* tip pose. Unless the
    arm is calibrated (its joint offset compensated), it holds the true grasp composed with
    the tip error of the hidden offset at ``measured_cp`` (DESIGN.md §5: millimetres), so it is
    valid only at the pose where it was measured (:meth:`valid_at`); ``calibrated`` None
    means the caller did not say, and is treated as uncalibrated. ``plausible`` compares the
    wire's distance from the jaw's pinch point with ``max_jaw_distance``, which for an
    uncalibrated arm must include the offset's worst tip displacement (else a correct
    estimate reads implausible).
    """

    T_tip_needle: np.ndarray
    grasp_arc_angle: float
    #: Distance (m) of the wire from the pinch point (``JAW_POINT_IN_TIP``).
    jaw_distance: float
    plausible: bool
    calibrated: bool | None = None
    #: The reported tip pose (arm base frame) the estimate was measured at.
    measured_cp: np.ndarray | None = None
    #: Distance (m) of the wire from the blades' holding stretch (``BLADE_Z_RANGE`` on tip z):
    #: what ``plausible`` compares with ``max_jaw_distance``.
    blade_distance: float = float("nan")

    @property
    def valid_only_where_measured(self) -> bool:
        """True unless the arm was calibrated: the absorbed offset error moves with the arm."""
        return self.calibrated is not True

    def valid_at(self, measured_cp: np.ndarray) -> bool:
        """Whether the estimate applies with the arm's reported tip pose ``measured_cp``: always
        for a calibrated arm, else only within ``SAME_POSE_*`` of where it was measured."""
        if not self.valid_only_where_measured:
            return True
        if self.measured_cp is None:
            return False
        M = np.asarray(measured_cp, float)
        dp = float(np.linalg.norm(M[:3, 3] - self.measured_cp[:3, 3]))
        c = (np.trace(self.measured_cp[:3, :3].T @ M[:3, :3]) - 1.0) / 2.0
        return dp <= SAME_POSE_POSITION and float(np.arccos(np.clip(c, -1, 1))) <= SAME_POSE_ANGLE


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
    calibrated: bool | None = None,
) -> InHandEstimate:
    """The in-hand transform plus the grasped arc angle; implausible if the wire is farther
    than ``max_jaw_distance`` from the stretch between the blades that holds it. ``calibrated``:
    whether the arm's offset is compensated (see :class:`InHandEstimate` for what an
    uncalibrated one absorbs)."""
    model = model or NeedleModel()
    T = in_hand_transform(T_world_needle, measured_cp, T_world_base)
    jaw_in_needle = invert(T)[:3, :3] @ JAW_POINT_IN_TIP + invert(T)[:3, 3]
    angles = np.linspace(model.tip_angle, model.base_angle, 721)
    arc = model.point_at(angles)
    d = np.linalg.norm(arc - jaw_in_needle, axis=1)
    in_tip = arc @ T[:3, :3].T + T[:3, 3]
    along = np.clip(in_tip[:, 2], *BLADE_Z_RANGE)
    blade = np.sqrt(in_tip[:, 0] ** 2 + in_tip[:, 1] ** 2 + (in_tip[:, 2] - along) ** 2)
    i, k = int(np.argmin(d)), int(np.argmin(blade))
    return InHandEstimate(
        T,
        float(angles[i]),
        float(d[i]),
        bool(blade[k] <= max_jaw_distance),
        calibrated,
        np.array(measured_cp, dtype=float),
        float(blade[k]),
    )
