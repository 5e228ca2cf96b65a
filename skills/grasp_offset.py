"""An uncalibrated arm's hidden offset, estimated from the needle it holds (provisional).

Every grasp of the task holds the needle the same way (:mod:`grasps`: the jaws across the
needle plane, the wire along the blades at the pinch point), at some arc angle. A confirmed
estimate of the held needle (two views agreed, :mod:`second_view`) therefore fixes where the
jaw truly is, up to that one angle; the arm's kinematics put the jaw there for one offset on
joints 1-3. Least squares over (offset, arc angle) within the task's bound: a fit that explains
the grasp to ``MAX_POSITION`` / ``MAX_ANGLE_DEG`` gives a provisional Δq̂ (the keypoint
calibration replaces it). Why: an uncalibrated arm's in-hand estimate carries to another pose
with an error of up to ~10 mm (dev trial 8140008: 7-10 mm at every handover presentation, which
put the needle on the image border), enough to lose the needle from view. Known kinematics, the
needle model and the estimate only; no ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from suture_bt.calibration.calibration_pose import OFFSET_BOUND
from suture_bt.geometry import NeedleModel
from suture_bt.kinematics import forward_kinematics
from suture_bt.skills.grasps import END_MARGIN, hand
from suture_bt.transforms import invert

#: A fit must explain the grasp this well (tip position m, tip orientation deg).
MAX_POSITION, MAX_ANGLE_DEG = 0.0015, 6.0
#: Weight of one degree of tip orientation against one millimetre of tip position.
DEG_PER_MM = 2.0


@dataclass(frozen=True)
class GraspOffset:
    """The offset (joints 1-3, added to the joints it was fitted at) and how well it fits."""

    offset: np.ndarray
    arc_angle: float
    position_error: float
    angle_error_deg: float

    def summary(self) -> str:
        dq = self.offset
        return (
            f"Δq ≈ ({np.rad2deg(dq[0]):+.2f}°, {np.rad2deg(dq[1]):+.2f}°, {1e3 * dq[2]:+.2f} mm), "
            f"grasp at {np.rad2deg(self.arc_angle):.0f}°, fit {1e3 * self.position_error:.2f} mm "
            f"/ {self.angle_error_deg:.1f}°"
        )


def _residual(x, base, q, T_needle, needle, pulling) -> np.ndarray:
    qq = np.array(q, dtype=float)
    qq[:3] += x[:3]
    T_tip = base @ forward_kinematics(qq)
    T_grasp = T_needle @ invert(hand(needle, x[3], pulling))
    dp = 1e3 * (T_tip[:3, 3] - T_grasp[:3, 3])
    rot = Rotation.from_matrix(T_grasp[:3, :3].T @ T_tip[:3, :3]).as_rotvec()
    return np.concatenate([dp, np.rad2deg(rot) / DEG_PER_MM])


def offset_from_grasp(
    base: np.ndarray,
    q: np.ndarray,
    T_world_needle: np.ndarray,
    needle: NeedleModel,
    bound: np.ndarray = OFFSET_BOUND,
) -> GraspOffset | None:
    """The offset on joints 1-3 (added to ``q``) that puts the jaw of the arm at ``base`` on
    the needle at ``T_world_needle`` as the task's grasps hold it; None when no offset within
    ``bound`` explains the grasp (a slipped or turned needle, or a wrong estimate)."""
    lo = np.r_[-bound, needle.tip_angle + END_MARGIN]
    hi = np.r_[bound, needle.base_angle]
    best = None
    for pulling in (False, True):
        for a0 in np.linspace(lo[3], hi[3], 4):
            fit = least_squares(
                _residual,
                np.r_[0.0, 0.0, 0.0, a0],
                bounds=(lo, hi),
                args=(base, q, T_world_needle, needle, pulling),
            )
            if best is None or fit.cost < best.cost:
                best = fit
    r = best.fun
    found = GraspOffset(
        best.x[:3].copy(),
        float(best.x[3]),
        float(np.linalg.norm(r[:3])) * 1e-3,
        float(np.linalg.norm(r[3:]) * DEG_PER_MM),
    )
    if found.position_error > MAX_POSITION or found.angle_error_deg > MAX_ANGLE_DEG:
        return None
    return found
