"""Which hand takes a needle lying free, and where: from above, or from the side on its edge.

A resting needle lying roughly flat (its plane within ``MAX_TILT`` of the tissue) is taken from
above: with the driving hand of :mod:`grasps` when its z axis points up, else with that hand
turned half a turn about the wire (:func:`turned_over_hand`: the only one whose jaws come from
above). A needle standing on its edge — a needle dropped on its way to an entry falls in its
own plane and comes to rest arched over the ridge — has its plane nearly upright, so the jaws,
which close across the needle plane, come in level from the side (either hand, whichever arm
reaches). The blades then open along the needle's radius, one of them below the wire, so the
grasp point must stand clear of the tissue: the arc angle nearest the asked one whose jaw region
keeps ``SIDE_CLEARANCE`` (wire) and ``BLADE_CLEARANCE`` (blades, along the whole approach)
above the phantom's known surface (:mod:`~suture_bt.geometry.tissue_surface`).

When the straight-down grasp of a flat needle is out of a wrist's reach, the same hand with its
jaws turned about the wire (``APPROACH_TILTS``) is offered next: the jaws still close across
the wire, coming in at a slant. A held-out campaign trial (seed 6580945831, the phantom moved
and turned) failed because a laid-down needle's straight grasp needed a wrist yaw of 90° from
PSM2 and 85.4° from PSM1, the limit 85°.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.skills.base import SkillFailure
from suture_bt.skills.grasps import END_MARGIN, GRASP_DEPTH, backed_off, hand, tip_goal
from suture_bt.transforms import invert, make_transform, rpy_to_matrix

#: Largest angle (rad) between the jaws' direction and straight down (−phantom up) for a grasp
#: from above; a needle tilted more stands on its edge and is taken from the side.
MAX_TILT = np.deg2rad(60.0)
#: The blades reach this far beyond the tip control point along tip z (m; the blade length
#: the world's grasp geometry uses).
BLADE_BEYOND_TIP = 0.0019
#: The jaws come to the grasp along their length from this far back (m), and the needle is
#: lifted this far along the phantom's up axis once held (m).
APPROACH, LIFT = 0.010, 0.015
#: A side grasp: the wire point stays this high above the tissue surface, and the blades (half
#: ``BLADE_HALF_SPREAD`` either side of the wire, from the hover to the grasp) this high (m).
SIDE_CLEARANCE, BLADE_CLEARANCE, BLADE_HALF_SPREAD = 0.002, 0.0005, 0.0012
#: Turns (rad) of a flat needle's grasp about the wire, tried in this order after the
#: straight-down one, and how much deeper (m) a turned grasp's blades may reach below the
#: tissue top than the straight one's (a blade swings down as the jaws turn).
APPROACH_TILTS = tuple(np.deg2rad(d) for d in (15.0, -15.0, 30.0, -30.0))
TILT_EXTRA_DEPTH = 0.0005
#: A pose lies flat on the tissue: plane tilt (rad) and centre-line height range (m).
FLAT_TILT, ON_SURFACE = np.deg2rad(15.0), (-0.0003, 0.0012)


@dataclass(frozen=True)
class RestingGrasp:
    """One way to take a resting needle: the hand (needle in the tip frame), its name, and
    the arc angle (rad) it holds."""

    T_tip_needle: np.ndarray
    hand: str
    arc_angle: float


def turned_over_hand(needle: NeedleModel, arc_angle: float) -> np.ndarray:
    """T_tip_needle of the driving hand turned half a turn about the wire (tip x): tip z =
    +needle z, the arc centre toward −tip y, the wire ``GRASP_DEPTH`` behind the tip."""
    a = float(arc_angle)
    tangent = np.array([np.sin(a), -np.cos(a), 0.0])
    radial = np.array([np.cos(a), np.sin(a), 0.0])
    R = np.stack([-tangent, -radial, [0.0, 0.0, 1.0]])  # rows: tip axes in the needle frame
    return make_transform(R, np.array([0.0, 0.0, -GRASP_DEPTH]) - R @ needle.point_at(a))


def tilted_about_wire(T_tip_needle: np.ndarray, tilt: float) -> np.ndarray:
    """The same hand with the jaws turned by ``tilt`` (rad) about the wire: about tip x
    through the held wire point, ``GRASP_DEPTH`` behind the tip."""
    turn = make_transform(rpy_to_matrix((tilt, 0.0, 0.0)))
    to_wire = make_transform(np.eye(3), np.array([0.0, 0.0, -GRASP_DEPTH]))
    new_tip_in_old = to_wire @ turn @ invert(to_wire)
    return invert(new_tip_in_old) @ T_tip_needle


def resting_tilt(ctx, T_world_needle: np.ndarray) -> tuple[float, bool]:
    """A resting needle's plane tilt from the tissue (rad) and whether its z points up."""
    z_up = float(T_world_needle[:3, 2] @ ctx.phantom.T_world_phantom[:3, 2])
    return float(np.arccos(min(1.0, abs(z_up)))), z_up >= 0.0


def lies_on_tissue(ctx, T_world_needle: np.ndarray) -> bool:
    """The needle pose lies flat on the tissue as a free needle comes to rest: its plane within
    ``FLAT_TILT`` of the tissue top and its whole centre-line ``ON_SURFACE`` (m) above the
    known surface under it (the wire's radius, give or take)."""
    tilt, _ = resting_tilt(ctx, T_world_needle)
    if tilt > FLAT_TILT:
        return False
    pts = ctx.needle.centerline(40) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
    h = height_above_tissue(ctx.phantom, pts)
    return bool(np.all((h >= ON_SURFACE[0]) & (h <= ON_SURFACE[1])))


def grasp_path(ctx, T_world_needle: np.ndarray, T_tip_needle: np.ndarray) -> list[np.ndarray]:
    """Tip poses of a pick-up: the hover back along the jaws, the grasp, the lift."""
    goal = tip_goal(T_world_needle, T_tip_needle)
    T_lift = goal.copy()
    T_lift[:3, 3] += LIFT * ctx.phantom.T_world_phantom[:3, 2]
    return [backed_off(goal, APPROACH), goal, T_lift]


def resting_grasps(ctx, T_world_needle: np.ndarray, arc_angle: float) -> list[RestingGrasp]:
    """The ways to take this resting needle near ``arc_angle``, preferred first (the caller
    tries them in order for reach); SkillFailure saying why when there is none."""
    tilt, z_up = resting_tilt(ctx, T_world_needle)
    a = float(arc_angle)
    if tilt <= MAX_TILT:
        name, make = ("driving", hand) if z_up else ("turned over", turned_over_hand)
        straight = make(ctx.needle, a)
        return [RestingGrasp(straight, name, a)] + _tilted(ctx, T_world_needle, straight, name, a)
    found, reasons = [], []
    for name, make in (("driving", hand), ("turned over", turned_over_hand)):
        angle, why = _side_angle(ctx, T_world_needle, make, a)
        if angle is None:
            reasons.append(f"{name} hand: {why}")
            continue
        found.append(RestingGrasp(make(ctx.needle, angle), f"{name}, from the side", angle))
    if not found:
        raise SkillFailure(
            f"standing on its edge (plane {np.rad2deg(tilt):.0f}° from the tissue) with no "
            f"side grasp clear of the tissue ({'; '.join(reasons)})"
        )
    return found


def _tilted(ctx, T_world_needle, straight, name: str, a: float) -> list[RestingGrasp]:
    """The straight grasp turned about the wire by each of APPROACH_TILTS whose blades reach
    no more than TILT_EXTRA_DEPTH deeper below the tissue than the straight grasp's."""
    floor = jaw_heights(ctx, T_world_needle, straight)[1] - TILT_EXTRA_DEPTH
    out = []
    for tilt in APPROACH_TILTS:
        T = tilted_about_wire(straight, tilt)
        if jaw_heights(ctx, T_world_needle, T)[1] >= floor:
            out.append(RestingGrasp(T, f"{name}, jaws turned {np.rad2deg(tilt):+.0f}°", a))
    return out


def _side_angle(ctx, T_world_needle: np.ndarray, make, asked: float):
    """The clear arc angle nearest ``asked`` for this hand, or (None, why)."""
    needle = ctx.needle
    angles = np.linspace(needle.tip_angle + END_MARGIN, needle.base_angle - END_MARGIN, 61)
    best = (-np.inf, 0.0)
    for a in sorted(angles, key=lambda c: abs(c - asked)):
        wire, blades = jaw_heights(ctx, T_world_needle, make(needle, a))
        if wire >= SIDE_CLEARANCE and blades >= BLADE_CLEARANCE:
            return float(a), ""
        best = max(best, (min(wire, blades), a))
    return None, (
        f"at best {1e3 * best[0]:.1f} mm above the tissue at {np.rad2deg(best[1]):.0f}° "
        f"(wire ≥ {1e3 * SIDE_CLEARANCE:g} mm, blades ≥ {1e3 * BLADE_CLEARANCE:g} mm)"
    )


def jaw_heights(ctx, T_world_needle: np.ndarray, T_tip_needle: np.ndarray):
    """Lowest height above the tissue of the held wire point, and of the blades' region swept
    from the hover to the grasp (m)."""
    goal = tip_goal(T_world_needle, T_tip_needle)
    R, p = goal[:3, :3], goal[:3, 3]
    wire = p - GRASP_DEPTH * R[:, 2]
    along = np.linspace(-APPROACH, BLADE_BEYOND_TIP, 12)
    spread = np.array([-BLADE_HALF_SPREAD, 0.0, BLADE_HALF_SPREAD])
    pts = (
        p[None, None]
        + along[:, None, None] * R[:, 2][None, None]
        + spread[None, :, None] * R[:, 1][None, None]
    ).reshape(-1, 3)
    h = height_above_tissue(ctx.phantom, np.vstack([wire[None], pts]))
    return float(h[0]), float(h[1:].min())
