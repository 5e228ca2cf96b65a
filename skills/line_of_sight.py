"""Keep the other arm out of the cameras' line of sight to the needle.

The cameras look at a presented needle along a cone from each eye; an arm waiting to take the
needle, or parked after calibration, can stand in that cone and hide the needle. From known
kinematics only (the arm's commanded tip pose and its remote centre of motion) this module
tells whether the tool's last centimetres lie within ``CLEARANCE`` of the sight line from
either eye to a target point, and finds a tip position (same orientation) that is clear,
pushed out perpendicular to the sight line toward the arm's own side.
"""

from __future__ import annotations

import numpy as np

from suture_bt.skills.base import Waiting
from suture_bt.skills.context import TaskContext
from suture_bt.skills.motion import feasible, move_to

#: Free radius kept around the sight line (m): the needle radius plus the jaws and a margin.
CLEARANCE = 0.022
#: Length of the tool checked behind the tip (m): the jaws, wrist and the start of the shaft.
TOOL_LENGTH = 0.04


def _eyes(ctx: TaskContext) -> list[np.ndarray]:
    model = ctx.camera.model
    return [model.left.T_world_cam[:3, 3], model.right.T_world_cam[:3, 3]]


def _tool_points(T_tip: np.ndarray, rcm: np.ndarray) -> np.ndarray:
    tip = T_tip[:3, 3]
    back = rcm - tip
    back /= np.linalg.norm(back)
    return tip + np.linspace(0.0, TOOL_LENGTH, 9)[:, None] * back


def intrusion(
    ctx: TaskContext,
    T_tip: np.ndarray,
    rcm: np.ndarray,
    target: np.ndarray,
    clearance: float = CLEARANCE,
) -> float:
    """How far (m) the tool reaches into a free radius (``clearance``) of a sight line from
    either eye to ``target`` (0: clear)."""
    worst = 0.0
    for eye in _eyes(ctx):
        ray = target - eye
        length = np.linalg.norm(ray)
        u = ray / length
        for p in _tool_points(T_tip, rcm):
            s = float(np.dot(p - eye, u))
            if 0.0 < s < length:  # between the eye and the target
                d = float(np.linalg.norm((p - eye) - s * u))
                worst = max(worst, clearance - d)
    return worst


def clear_tip_pose(
    ctx: TaskContext, T_tip: np.ndarray, rcm: np.ndarray, target: np.ndarray
) -> np.ndarray | None:
    """``T_tip`` moved out of the sight lines to ``target`` (None when already clear)."""
    if intrusion(ctx, T_tip, rcm, target) <= 0.0:
        return None
    eye = np.mean(_eyes(ctx), axis=0)
    u = (target - eye) / np.linalg.norm(target - eye)
    # Toward the arm's own side (its remote centre): the shaft behind the tip leaves too.
    away = (rcm - eye) - np.dot(rcm - eye, u) * u
    away /= np.linalg.norm(away)
    T = np.array(T_tip, dtype=float)
    for _ in range(10):
        if intrusion(ctx, T, rcm, target) <= 0.0:
            return T
        T[:3, 3] += 0.006 * away
    return T


def make_way(ctx: TaskContext, target: np.ndarray, keep: str | None = None) -> list[Waiting]:
    """Moves that take every arm but ``keep`` out of the cameras' sight of ``target``."""
    moves = []
    for name, other in ctx.arms.items():
        if name == keep:
            continue
        T = clear_tip_pose(ctx, other.commanded_tip_world(), other.base_frame()[:3, 3], target)
        if T is not None and not feasible(other, [T]):
            moves.append(move_to(ctx.clock, other, [T], "make way for the cameras"))
    return moves
