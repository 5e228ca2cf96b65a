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

from suture_bt.kinematics import L_PITCH2YAW, frame_transforms
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
    return make_way_for(ctx, [target], keep)


def make_way_for(
    ctx: TaskContext, targets: list[np.ndarray], keep: str | None = None
) -> list[Waiting]:
    """Moves that take every arm but ``keep`` out of the cameras' sight of every target (each
    arm cleared of one target after the other)."""
    moves = []
    for name, other in ctx.arms.items():
        if name == keep:
            continue
        rcm = other.base_frame()[:3, 3]
        T = None  # the tip moved clear of the targets so far (None: already clear)
        for target in targets:
            moved = clear_tip_pose(
                ctx, other.commanded_tip_world() if T is None else T, rcm, target
            )
            T = T if moved is None else moved
        if T is not None and not feasible(other, [T]):
            moves.append(move_to(ctx.clock, other, [T], "make way for the cameras"))
    return moves


#: Places along each tool, behind its tip (m), whose shadow on a plane :func:`hidden_behind`
#: reports: the jaws and the clevis, where a needle lying under an arm hides.
HIDING_PLACES = (0.0, 0.01, 0.02)


def hidden_behind(
    ctx: TaskContext, point_on_plane: np.ndarray, normal: np.ndarray
) -> list[np.ndarray]:
    """Points of a plane (e.g. the tissue top) that each arm's jaws and clevis hide from the
    cameras: where the sight line from between the eyes through each place of
    ``HIDING_PLACES`` meets the plane behind the tool (commanded poses, known geometry)."""
    eye = np.mean(_eyes(ctx), axis=0)
    out = []
    for arm in ctx.arms.values():
        T_tip, rcm = arm.commanded_tip_world(), arm.base_frame()[:3, 3]
        back = (rcm - T_tip[:3, 3]) / np.linalg.norm(rcm - T_tip[:3, 3])
        for d in HIDING_PLACES:
            ray = T_tip[:3, 3] + d * back - eye
            t = ray_meets_plane(eye, ray, point_on_plane, normal)
            if t is not None and t > 1.0:  # the plane lies behind the tool
                out.append(eye + t * ray)
    return out


def ray_meets_plane(
    origin: np.ndarray, ray: np.ndarray, point_on_plane: np.ndarray, normal: np.ndarray
) -> float | None:
    """t such that ``origin + t · ray`` lies on the plane (None: the ray runs along it)."""
    n = np.asarray(normal, dtype=float)
    along = float(ray @ n)
    if abs(along) < 1e-9:
        return None
    return float((np.asarray(point_on_plane, dtype=float) - origin) @ n) / along


#: The holder's own tool as the cameras see it around a presented needle (known instrument
#: geometry, m): the shaft (radius 4.2 mm, ending ``SHAFT_END`` before the wrist-pitch axis)
#: and the clevis (a block about 13 × 4.4 × 6 mm between the pitch and yaw axes), each as a
#: capsule with ``MARGIN`` added. The jaws hide only the wire where it is held.
SHAFT_RADIUS, SHAFT_END, SHAFT_SEEN = 0.0042, 0.006, 0.08
CLEVIS_HALF_LENGTH, CLEVIS_RADIUS = 0.0065, 0.0037
MARGIN = 0.0005
#: A point counts as hidden when the sight line meets the tool this far in front of it (m).
IN_FRONT = 0.002


def _closest_on_segments(p0, p1, q0, q1):
    """Distances between segments p0→p1 (N×3 each) and the one segment q0→q1, and the
    parameter along each p segment (0 at p0) of the closest point."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.einsum("ij,ij->i", d1, d1)
    e = max(float(d2 @ d2), 1e-18)
    f = r @ d2
    c = np.einsum("ij,ij->i", d1, r)
    b = d1 @ d2
    denom = a * e - b * b
    s = np.where(denom > 1e-18, np.clip((b * f - c * e) / np.maximum(denom, 1e-18), 0, 1), 0.0)
    t = np.clip((b * s + f) / e, 0.0, 1.0)
    s = np.clip((b * t - c) / a, 0.0, 1.0)
    gap = (p0 + s[:, None] * d1) - (q0 + t[:, None] * d2)
    return np.linalg.norm(gap, axis=1), s


def own_tool_capsules(T_world_base: np.ndarray, q: np.ndarray) -> list[tuple]:
    """The holding tool's shaft and clevis at joints ``q`` as (start, end, radius), world."""
    frames = [T_world_base @ F for F in frame_transforms(q)]
    F4, F5 = frames[3], frames[4]  # tool roll (its origin: the wrist-pitch axis), wrist pitch
    shaft_end = F4[:3, 3] - SHAFT_END * F4[:3, 2]
    shaft_seen = shaft_end - SHAFT_SEEN * F4[:3, 2]
    clevis = F5[:3, 3] + 0.5 * L_PITCH2YAW * F5[:3, 0]
    half = CLEVIS_HALF_LENGTH * F5[:3, 0]
    return [
        (shaft_end, shaft_seen, SHAFT_RADIUS + MARGIN),
        (clevis - half, clevis + half, CLEVIS_RADIUS + MARGIN),
    ]


def hidden_by_own_tool(
    ctx: TaskContext, T_world_base: np.ndarray, q: np.ndarray, points: np.ndarray
) -> float:
    """Share (worse eye) of ``points`` (world, a held needle's possible places) hidden from
    the cameras by the holding tool's shaft and clevis at joints ``q``: the sight line
    passes through them in front of the point."""
    pts = np.asarray(points, dtype=float)
    capsules = own_tool_capsules(T_world_base, q)
    worst = 0.0
    for eye in _eyes(ctx):
        p0 = np.broadcast_to(eye, pts.shape)
        length = np.linalg.norm(pts - eye, axis=1)
        hidden = np.zeros(len(pts), bool)
        for a, b, radius in capsules:
            dist, s = _closest_on_segments(p0, pts, a, b)
            hidden |= (dist < radius) & (s * length < length - IN_FRONT)
        worst = max(worst, float(np.mean(hidden)))
    return worst
