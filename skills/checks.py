"""Confirmations from evidence a real robot has: the jaw's measured angle and the images.

Each returns ``(ok, detail)``; skills record them with :meth:`Skill.check`, which fails the
skill with the detail when ``ok`` is false. None of them can only say yes: each has a test in
which it must say no.
"""

from __future__ import annotations

import numpy as np

from suture_bt.geometry import NeedleModel, Port
from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.transforms import invert, rotation_angle

#: Closed on the 0.72 mm wire the blades stop at about 0.08 rad; closed empty they reach 0.
JAW_ON_WIRE_MIN = 0.03
#: A jaw above this angle is not closed at all (the dVRK's closing threshold).
JAW_CLOSED_MAX = 0.2
#: SRC throw rule (DESIGN.md §5): lateral distance at the exit and tip out past it.
MAX_LATERAL = 0.0025
MIN_TIP_OUT = 0.005
#: An image estimate agrees with the pose predicted from the arm within these (m, deg).
AGREE_POSITION = 0.003
AGREE_ANGLE_DEG = 12.0
#: A needle this close to a planned circle's pose at its own sweep angle (m, deg) lies on it.
ON_ARC_M, ON_ARC_DEG = 0.003, 15.0


def jaw_holds_wire(jaw_angle: float) -> tuple[bool, str]:
    """A closed jaw that stopped short of empty-closed has something between its blades."""
    if jaw_angle > JAW_CLOSED_MAX:
        return False, f"jaw open at {jaw_angle:.3f} rad (closed ≤ {JAW_CLOSED_MAX} rad)"
    ok = jaw_angle >= JAW_ON_WIRE_MIN
    state = "stopped on the wire" if ok else "closed empty"
    return ok, f"jaw {state} at {jaw_angle:.3f} rad (wire ≥ {JAW_ON_WIRE_MIN} rad)"


def pose_difference(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """(centre distance m, rotation deg) between two needle poses."""
    dp = float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]))
    return dp, float(np.rad2deg(rotation_angle(T_a[:3, :3], T_b[:3, :3])))


def poses_agree(T_seen: np.ndarray, T_predicted: np.ndarray) -> tuple[bool, str]:
    """The needle seen where the arm's motion says it should be (it moved with the gripper)."""
    dp, da = pose_difference(T_seen, T_predicted)
    ok = dp <= AGREE_POSITION and da <= AGREE_ANGLE_DEG
    return ok, f"seen {dp * 1e3:.1f} mm / {da:.1f}° from where the gripper put it"


def stayed_in_place(T_seen: np.ndarray, T_before: np.ndarray) -> tuple[bool, str]:
    """The needle is still where it was (same centre, same plane), e.g. after a handover.

    The turn within its own plane is left free: the earlier estimate was made with the other
    jaw over part of the arc, where an end's place along the circle is least certain.
    """
    dp = float(np.linalg.norm(T_seen[:3, 3] - T_before[:3, 3]))
    cos = float(np.clip(abs(T_seen[:3, 2] @ T_before[:3, 2]), -1.0, 1.0))
    tilt = float(np.rad2deg(np.arccos(cos)))
    ok = dp <= AGREE_POSITION and tilt <= AGREE_ANGLE_DEG
    return ok, f"seen {dp * 1e3:.1f} mm away, its plane turned {tilt:.1f}°"


def tip_out_past_exit(
    T_world_needle: np.ndarray, needle: NeedleModel, exit_port: Port
) -> tuple[bool, str, dict]:
    """Where the seen arc crosses the exit plane (lateral) and how far the tip stands out."""
    angles = np.linspace(needle.tip_angle, needle.base_angle, 400)
    pts = needle.point_at(angles) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
    local = (pts - exit_port.position) @ exit_port.T[:3, :3]  # port frame
    z = local[:, 2]
    if z[0] <= 0.0:
        return False, f"tip not out: {-z[0] * 1e3:.1f} mm under {exit_port.name}'s surface", {}
    below = np.nonzero(z <= 0.0)[0]
    if len(below) == 0:
        return False, f"the seen needle does not pass through {exit_port.name}'s surface", {}
    i = int(below[0])
    s = z[i - 1] / (z[i - 1] - z[i])
    c = local[i - 1] + s * (local[i] - local[i - 1])
    lateral = float(np.hypot(c[0], c[1]))
    tip_out = float(np.linalg.norm(local[0] - c))
    ok = lateral <= MAX_LATERAL and tip_out >= MIN_TIP_OUT
    detail = (
        f"seen crossing {exit_port.name} {lateral * 1e3:.2f} mm from it "
        f"(≤ {MAX_LATERAL * 1e3:.1f}), tip {tip_out * 1e3:.1f} mm out (≥ {MIN_TIP_OUT * 1e3:.0f})"
    )
    return ok, detail, {"lateral_mm": 1e3 * lateral, "tip_out_mm": 1e3 * tip_out}


def clear_of_tissue(
    T_world_needle: np.ndarray, needle: NeedleModel, T_world_phantom: np.ndarray, ports: list[Port]
) -> tuple[bool, str]:
    """Every point of the seen needle is above the tissue: above the flat top, or above one
    of the ridge flanks (the ridge lies under both flank planes of a pair)."""
    pts = needle.centerline(60) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
    local = pts @ invert(T_world_phantom)[:3, :3].T + invert(T_world_phantom)[:3, 3]
    above_top = local[:, 2] > TISSUE_TOP_Z
    above_flank = np.zeros(len(pts), bool)
    for p in ports:
        above_flank |= (pts - p.position) @ p.normal > 0.0
    ok = bool(np.all(above_top & above_flank))
    worst = float(np.min(local[:, 2] - TISSUE_TOP_Z))
    return ok, f"lowest point of the seen needle {worst * 1e3:+.1f} mm from the tissue top"


def on_planned_circle(arc, T_world_needle: np.ndarray, pair: int) -> tuple[str, float]:
    """('' or why not, the sweep angle) of a needle pose on a pair's planned circle ``arc``
    (a :class:`~suture_bt.planning.NeedleArc`): its orientation says how far along the
    circle it is; there it must lie within ``ON_ARC_M`` / ``ON_ARC_DEG`` of the circle."""
    phi, turn = arc.sweep_angle_of(T_world_needle[:3, :3])
    off = float(np.linalg.norm(T_world_needle[:3, 3] - arc.needle_pose(phi)[:3, 3]))
    if off > ON_ARC_M or np.rad2deg(turn) > ON_ARC_DEG:
        return (
            f"not on pair {pair}'s circle ({1e3 * off:.1f} mm, {np.rad2deg(turn):.0f}° off; "
            f"≤ {1e3 * ON_ARC_M:g} mm, {ON_ARC_DEG:g}°)"
        ), phi
    return "", phi


def last_seen_at_exit(reports: list[dict], pair: int, since: float) -> dict | None:
    """What the latest insertion of ``pair`` (started at or after ``since``) saw at the exit:
    its report's ``seen`` numbers (``lateral_mm``, ``tip_out_mm``), or None."""
    for r in reversed(reports):
        if r.get("t_start", -1.0) < since:
            break
        if r.get("skill") == "insert" and r.get("pair") == pair and r.get("seen"):
            return r["seen"]
    return None


def seen_out_past_exit(seen: dict | None) -> bool:
    """The tip was seen crossing the exit within the rule's lateral distance and out past it:
    backing it out would re-enter the tissue there."""
    return bool(
        seen
        and seen.get("lateral_mm", np.inf) <= 1e3 * MAX_LATERAL
        and seen.get("tip_out_mm", 0.0) > 0.0
    )
