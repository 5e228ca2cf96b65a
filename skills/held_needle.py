"""Where a held needle may be: its places relative to the jaw and their height above the tissue.

With the jaw at a given pose the held needle lies on its believed arc or, its in-hand pose
unknown, anywhere on the circle on either side of the jaw. The presentation poses
(:mod:`presentation`) are judged over these places; they live here so that module keeps to
choosing the poses.
"""

from __future__ import annotations

import numpy as np

from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.grasps import GRASP_DEPTH
from suture_bt.skills.offset_evidence import held_circles

#: Samples of the needle's circle (unknown grasp) and of its arc (known grasp).
CIRCLE_SAMPLES = 16
ARC_SAMPLES = 9


def needle_place_sets(ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray) -> list[np.ndarray]:
    """The places the held needle may be with the jaw at ``T_tip`` (world points, before any
    offset displacement), one set per way it may be held: its believed arc, or, unknown, the
    whole circle on either side of the jaw (the jaw holds the wire along tip x, the centre
    lies one radius along ±tip y), each with the pinch point."""
    b = ctx.belief
    r = ctx.needle.radius
    if b is not None and b.holder == arm.name and b.T_tip_needle is not None:
        T_needle = T_tip @ b.T_tip_needle
        arc = ctx.needle.point_at(
            np.linspace(ctx.needle.tip_angle, ctx.needle.base_angle, ARC_SAMPLES)
        )
        return [arc @ T_needle[:3, :3].T + T_needle[:3, 3]]
    pinch = T_tip[:3, 3] - GRASP_DEPTH * T_tip[:3, 2]
    sides = np.split(held_circles(T_tip, r, CIRCLE_SAMPLES), 2)
    return [np.vstack([pinch[None], side]) for side in sides]


def needle_places(ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray) -> np.ndarray:
    """All the world points of :func:`needle_place_sets`."""
    return np.vstack(needle_place_sets(ctx, arm, T_tip))


def clearance_at(
    ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray, displacements: np.ndarray
) -> float:
    """Least height (m) of the held needle above the tissue over its possible places."""
    pts = needle_places(ctx, arm, T_tip)
    moved = (pts[:, None, :] + displacements[None]).reshape(-1, 3)
    return float(np.min(height_above_tissue(ctx.phantom, moved)))
