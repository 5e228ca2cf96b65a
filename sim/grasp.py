"""Does closing the jaws grasp the needle? Pure geometry in the tool-tip frame (no pybullet).

Tip frame = frame 7 of :mod:`suture_bt.kinematics`: the jaws pivot about the wrist-yaw axis
(−x of the tip frame), run along +z and close along ±y onto the tip x-z plane, the *pinch
plane*. The *pinch line* is the tip z axis. Tolerances chosen here (documented in DESIGN terms):

* the nearest point of the needle centre-line to the pinch line lies within
  ``GRASP_TOLERANCE`` = 1.5 mm of it (so within the 3 mm blade width and with the wire inside
  the opening), and at a height ``z`` along the jaw inside ``GRASP_Z_RANGE`` (from 3 mm past the
  pivot to the blade end, 1.9 mm beyond the control point);
* the wire there makes at least 45° with the closing direction (tip y): a wire running
  between the blades is squeezed, one pointing at a blade is not;
* the jaw angle is at or below the closing threshold (0.2 rad).

On success the in-hand pose is what the geometry gives, with one physical correction: the
closing blades push the wire onto the pinch plane, so the needle is translated along tip y by
the wire's offset from that plane (at most 1.5 mm). No canonical pose is imposed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.geometry.needle import NeedleModel
from suture_bt.kinematics.psm import JAW_CLOSED_THRESHOLD, L_YAW2CTRLPNT
from suture_bt.transforms import invert

#: Largest distance (m) between the needle centre-line and the pinch line that still grasps.
GRASP_TOLERANCE = 0.0015
#: Usable stretch of the blades along tip z (m): 3 mm past the pivot up to the blade end.
GRASP_Z_RANGE = (-L_YAW2CTRLPNT + 0.003, 0.0019)
#: Smallest angle (rad) between the wire and the closing direction.
MIN_WIRE_ANGLE_TO_CLOSING = np.deg2rad(45.0)
#: Centre-line samples for the nearest-point search (≈ 20 µm apart), refined analytically.
_N_SAMPLES = 1101


@dataclass(frozen=True)
class GraspCheck:
    """Outcome of a grasp attempt; ``T_tip_needle`` and ``arc_angle`` are set when ok."""

    ok: bool
    reason: str
    T_tip_needle: np.ndarray | None = None
    arc_angle: float | None = None
    distance: float | None = None


def _nearest_to_pinch_line(model: NeedleModel, T_tip_needle: np.ndarray) -> tuple[float, float]:
    """Arc angle of the centre-line point nearest the pinch segment, and that distance."""
    a = np.linspace(model.base_angle, model.tip_angle, _N_SAMPLES)
    pts = model.point_at(a) @ T_tip_needle[:3, :3].T + T_tip_needle[:3, 3]
    z = np.clip(pts[:, 2], *GRASP_Z_RANGE)
    d = np.sqrt(pts[:, 0] ** 2 + pts[:, 1] ** 2 + (pts[:, 2] - z) ** 2)
    i = int(np.argmin(d))
    # Refine around the best sample (golden-section would do; a fine local grid is enough).
    lo, hi = a[max(i - 1, 0)], a[min(i + 1, len(a) - 1)]
    af = np.linspace(lo, hi, 201)
    pf = model.point_at(af) @ T_tip_needle[:3, :3].T + T_tip_needle[:3, 3]
    zf = np.clip(pf[:, 2], *GRASP_Z_RANGE)
    df = np.sqrt(pf[:, 0] ** 2 + pf[:, 1] ** 2 + (pf[:, 2] - zf) ** 2)
    j = int(np.argmin(df))
    return float(af[j]), float(df[j])


def check_grasp(
    T_world_tip: np.ndarray,
    jaw_angle: float,
    T_world_needle: np.ndarray,
    model: NeedleModel,
) -> GraspCheck:
    """Whether closing the jaws at ``T_world_tip`` grasps the needle, and the in-hand pose."""
    T_world_tip = np.asarray(T_world_tip, dtype=float)
    T_world_needle = np.asarray(T_world_needle, dtype=float)
    if T_world_tip.shape != (4, 4) or T_world_needle.shape != (4, 4):
        raise ValueError("check_grasp needs 4×4 tip and needle poses")
    if not np.isfinite(jaw_angle):
        raise ValueError(f"jaw angle must be finite, got {jaw_angle!r}")
    if jaw_angle > JAW_CLOSED_THRESHOLD:
        return GraspCheck(False, f"jaw not closed ({jaw_angle:.3f} rad > {JAW_CLOSED_THRESHOLD})")
    T_tip_needle = invert(T_world_tip) @ T_world_needle
    angle, dist = _nearest_to_pinch_line(model, T_tip_needle)
    p = T_tip_needle[:3, :3] @ model.point_at(angle) + T_tip_needle[:3, 3]
    if dist > GRASP_TOLERANCE:
        return GraspCheck(
            False,
            f"wire {dist * 1e3:.2f} mm from the jaw's pinch line "
            f"(tolerance {GRASP_TOLERANCE * 1e3:.1f} mm)",
            arc_angle=angle,
            distance=dist,
        )
    if not GRASP_Z_RANGE[0] <= p[2] <= GRASP_Z_RANGE[1]:
        where = "beyond the jaw tip" if p[2] > GRASP_Z_RANGE[1] else "too close to the pivot"
        return GraspCheck(False, f"wire {where} (z = {p[2] * 1e3:.2f} mm in the tip frame)")
    t = T_tip_needle[:3, :3] @ model.tangent_at(angle)
    angle_to_closing = float(np.arccos(min(1.0, abs(t[1]))))
    if angle_to_closing < MIN_WIRE_ANGLE_TO_CLOSING:
        return GraspCheck(
            False,
            f"wire points at a blade ({np.rad2deg(angle_to_closing):.0f}° from the closing "
            f"direction < {np.rad2deg(MIN_WIRE_ANGLE_TO_CLOSING):.0f}°)",
            arc_angle=angle,
            distance=dist,
        )
    T_grasped = T_tip_needle.copy()
    T_grasped[1, 3] -= p[1]  # the blades push the wire onto the pinch plane
    return GraspCheck(
        True,
        f"wire between the jaws ({dist * 1e3:.2f} mm from the pinch line)",
        T_tip_needle=T_grasped,
        arc_angle=angle,
        distance=dist,
    )
