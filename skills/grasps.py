"""Where and how a jaw takes the needle: hands (needle in the tip frame) at an arc angle.

Both hands put the jaws across the needle plane (tip z = −needle z) with the wire along tip x,
``GRASP_DEPTH`` behind the tip control point (inside the blades). The *driving* hand (arc centre
toward +tip y) is the one the insertion planner uses for the inserting arm; the *pulling* hand
is the same turned half a turn about tip z, as the other arm takes the needle out past an exit.
"""

from __future__ import annotations

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.kinematics.psm import GRASP_DEPTH
from suture_bt.planning import NeedleArc
from suture_bt.transforms import invert, make_transform

#: Clear arc (rad) kept between the jaws and the needle's ends.
END_MARGIN = np.deg2rad(8.0)
#: Smallest arc angle (rad) between two jaws holding the needle at once.
MIN_JAW_SEPARATION = np.deg2rad(35.0)
#: Extra arc beyond the planner's grasp limit for the inserting grasp (rad): covers the
#: in-plane error (up to about 12°) of an estimate made with another jaw near the tip.
INSERT_GRASP_MARGIN = np.deg2rad(12.0)
#: Jaw clearance from the entry that the planner's grasp limit keeps (m).
JAW_CLEARANCE = 0.0015
#: The pulling arm takes an emerged needle this far behind its tip (rad of arc).
PULL_GRASP_OFFSET = np.deg2rad(15.0)


def hand(needle: NeedleModel, arc_angle: float, pulling: bool = False) -> np.ndarray:
    """T_tip_needle for a grasp at ``arc_angle`` (see the module docstring)."""
    a = float(arc_angle)
    tangent = np.array([np.sin(a), -np.cos(a), 0.0])
    radial = np.array([np.cos(a), np.sin(a), 0.0])
    rows = [tangent, -radial] if pulling else [-tangent, radial]
    R = np.stack([*rows, [0.0, 0.0, -1.0]])  # rows: tip axes in the needle frame
    return make_transform(R, np.array([0.0, 0.0, -GRASP_DEPTH]) - R @ needle.point_at(a))


def pulling_grasp_angle(needle: NeedleModel) -> float:
    """Arc angle where the arm that takes an emerged needle out past an exit holds it."""
    return float(needle.tip_angle + PULL_GRASP_OFFSET)


def pulling_hand(needle: NeedleModel) -> np.ndarray:
    """T_tip_needle of the arm that takes an emerged needle out past an exit."""
    return hand(needle, pulling_grasp_angle(needle), pulling=True)


def tip_goal(T_world_needle: np.ndarray, T_tip_needle: np.ndarray) -> np.ndarray:
    """World tip pose that holds the needle at ``T_world_needle`` with this hand."""
    return np.asarray(T_world_needle) @ invert(T_tip_needle)


def backed_off(T_world_tip: np.ndarray, distance: float) -> np.ndarray:
    """The tip pose ``distance`` back along its own −z (jaws come in along their length)."""
    T = np.array(T_world_tip, dtype=float)
    T[:3, 3] -= distance * T[:3, 2]
    return T


def held_arc_angle(needle: NeedleModel, T_tip_needle: np.ndarray) -> float:
    """Arc angle of the needle point nearest the jaw's pinch point; off the arc, the nearer
    end (by angle around the circle, so a point just past the tip is the tip on either side
    of angle zero)."""
    p = invert(T_tip_needle) @ np.array([0.0, 0.0, -GRASP_DEPTH, 1.0])
    a = float(np.arctan2(p[1], p[0])) % (2 * np.pi)
    if needle.tip_angle <= a <= needle.base_angle:
        return a
    past_tip = (needle.tip_angle - a) % (2 * np.pi)
    past_base = (a - needle.base_angle) % (2 * np.pi)
    return float(needle.tip_angle if past_tip <= past_base else needle.base_angle)


def insertion_grasp_angle(arc: NeedleArc) -> float:
    """Arc angle to hold for this pair: past the planner's grasp limit by a margin."""
    needle = arc.needle
    need = needle.tip_angle + arc.insert_end_angle + JAW_CLEARANCE / needle.radius
    return float(min(need + INSERT_GRASP_MARGIN, needle.base_angle - END_MARGIN))


def free_angle(needle: NeedleModel, avoid: list[float]) -> float:
    """The arc angle farthest from every angle in ``avoid`` (other jaws now or later)."""
    lo, hi = needle.tip_angle + END_MARGIN, needle.base_angle - END_MARGIN
    cands = np.linspace(lo, hi, 200)
    if not avoid:
        return float(0.5 * (lo + hi))
    gaps = np.min(np.abs(cands[:, None] - np.asarray(avoid)[None]), axis=1)
    return float(cands[int(np.argmax(gaps))])
