"""Presentation poses: where an arm holds the needle so the cameras see the whole arc.

At the SRC Task 3 start the held needle is 30-48 mm from the cameras and edge-on, where the
localiser refuses or errs; held 55-85 mm away with its plane turned toward the cameras it is
localised to about 0.1 mm / 0.5° (measured). A presentation pose puts the jaw's pinch point at
``DEPTH`` in front of the left camera, high enough above the known ports to be clear of the
tissue, and turns the jaw (whose axis is the needle plane's normal) from a small set of
directions toward the line of sight. Everything is derived from the camera model and the port
frames, so a moved or rotated phantom or another arm works the same.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from suture_bt.kinematics import UnreachablePoseError, inverse_kinematics
from suture_bt.planning import to_base
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.grasps import GRASP_DEPTH
from suture_bt.skills.motion import feasible
from suture_bt.skills.tip_uncertainty import tip_margin
from suture_bt.transforms import make_transform

#: Distance of the pinch point in front of the left camera (m, along its optical axis).
DEPTH = 0.062
#: Smallest height of the pinch point above every port, along the phantom's up axis (m).
MIN_CLEARANCE = 0.02
#: Smallest height of the held needle's lowest point above the highest port when presented
#: (m): a presentation that would hang it lower is tried last.
MIN_NEEDLE_CLEARANCE = 0.004
#: Image-plane offsets (camera x, y; m) tried for the pinch point, nearest the centre first.
OFFSETS = [(0.0, -0.004 * k) for k in range(0, 8)]
#: Jaw-axis directions in the camera frame (x toward the arm's own side is s = +1).
DIRECTIONS = [
    (-1.0, 0.0, 1.0),
    (-0.5, 0.0, 1.0),
    (0.0, 0.0, 1.0),
    (0.0, -1.0, 1.0),
    (0.0, -0.5, 1.0),
    (-1.0, -1.0, 1.0),
    (-0.5, 0.5, 1.0),
]
ROLLS = np.deg2rad(np.arange(0.0, 360.0, 45.0))


def presentation_point(ctx: TaskContext) -> np.ndarray:
    """World point for the pinch point: in view, ``DEPTH`` away, clear of the tissue."""
    cam = ctx.camera.model.left.T_world_cam
    up = ctx.phantom.T_world_phantom[:3, 2]
    ports = np.array([p.position for p in ctx.phantom.ports()])
    best, best_clear = None, -np.inf
    for x, y in OFFSETS:
        p = (cam @ np.array([x, y, DEPTH, 1.0]))[:3]
        clear = float(np.min((p - ports) @ up))
        if clear >= MIN_CLEARANCE:
            return p
        if clear > best_clear:
            best, best_clear = p, clear
    return best


def _side(ctx: TaskContext, arm: ArmHandle) -> float:
    """+1 when the arm's base lies on the camera's +x side."""
    cam = ctx.camera.model.left
    return 1.0 if (cam.T_cam_world @ np.r_[arm.base_frame()[:3, 3], 1.0])[0] >= 0 else -1.0


def candidate_poses(ctx: TaskContext, arm: ArmHandle) -> list[np.ndarray]:
    """Tip poses that present a held needle, reachable at their goal, least wrist bend first."""
    cam_R = ctx.camera.model.left.T_world_cam[:3, :3]
    point = presentation_point(ctx)
    s = _side(ctx, arm)
    base = arm.base_frame()
    q_now = arm.servo.setpoint_jp()
    b = ctx.belief
    unknown = b is None or b.holder != arm.name or b.T_tip_needle is None
    scored = []
    for d in DIRECTIONS:
        z = cam_R @ (np.array([s * d[0], d[1], d[2]]) / np.linalg.norm(d))
        a = np.cross(z, cam_R[:, 1])
        a /= np.linalg.norm(a)
        b = np.cross(z, a)
        for roll in ROLLS:
            x = np.cos(roll) * a + np.sin(roll) * b
            T = make_transform(np.column_stack([x, np.cross(z, x), z]), point + GRASP_DEPTH * z)
            try:
                q = inverse_kinematics(to_base(T, base), q_now)
            except UnreachablePoseError:
                continue
            bend = abs(q[4]) + abs(q[5]) + 0.3 * abs(q[3] - q_now[3])
            low, band = False, 0.0
            if unknown:  # among those that may hang low: higher first, by 5 mm bands
                clear = needle_clearance(ctx, arm, T)
                low = clear < MIN_NEEDLE_CLEARANCE
                band = -np.floor(clear / 0.005) if low else 0.0
            scored.append((low, band, bend, len(scored), T))
    # A needle not localised yet: poses that may hang it into the tissue go last, however
    # little they bend (once its in-hand pose is known, least bend decides, as the views of
    # the handovers were chosen for).
    scored.sort(key=lambda c: c[:4])
    return [T for *_, T in scored]


def needle_clearance(ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray) -> float:
    """Height (m) of the held needle's lowest point above the highest port, with the jaw at
    ``T_tip`` (less the tip margin of an uncalibrated arm). Known in-hand transform: its arc;
    unknown: the worst of both hands — the jaw holds the wire along tip x, so the arc's centre
    lies one radius along ±tip y and the needle may reach a radius below that."""
    up = ctx.phantom.T_world_phantom[:3, 2]
    top = max(float(p.position @ up) for p in ctx.phantom.ports())
    b = ctx.belief
    r = ctx.needle.radius
    if b is not None and b.holder == arm.name and b.T_tip_needle is not None:
        T_needle = T_tip @ b.T_tip_needle
        arc = ctx.needle.point_at(np.linspace(ctx.needle.tip_angle, ctx.needle.base_angle, 9))
        lowest = float(np.min((arc @ T_needle[:3, :3].T + T_needle[:3, 3]) @ up))
    else:
        lowest = float(T_tip[:3, 3] @ up) - r * abs(float(T_tip[:3, 1] @ up)) - r
    return lowest - top - tip_margin(arm)


def choose(
    ctx: TaskContext, arm: ArmHandle, accept: Callable[[np.ndarray], str] | None = None
) -> tuple[list[np.ndarray], list[str]]:
    """Candidate poses the arm can move to now (and that ``accept`` passes: '' = ok), in order,
    plus the reasons the others were dropped."""
    good, why = [], []
    for T in candidate_poses(ctx, arm):
        reason = feasible(arm, [T]) or (accept(T) if accept else "")
        if reason:
            why.append(reason)
        else:
            good.append(T)
        if len(good) >= 5:
            break
    return good, why


def lifted_first(ctx: TaskContext, arm: ArmHandle, T_goal: np.ndarray) -> list[np.ndarray]:
    """Waypoints to a presentation pose: straight up first (along the phantom's up axis) when
    the held needle (as believed; not yet localised: a needle diameter below the jaw) is lower
    than ``MIN_CLEARANCE`` (plus, uncalibrated, the tip's worst offset displacement) above the
    highest port, so it is not dragged through the tissue on the way."""
    up = ctx.phantom.T_world_phantom[:3, 2]
    ports = np.array([p.position for p in ctx.phantom.ports()])
    T_now = arm.commanded_tip_world()
    belief = ctx.belief
    if belief is not None and belief.holder == arm.name and belief.T_tip_needle is not None:
        T_needle = T_now @ belief.T_tip_needle  # the held needle hangs below the jaw
        arc = ctx.needle.point_at(np.linspace(ctx.needle.tip_angle, ctx.needle.base_angle, 9))
        low = list(arc @ T_needle[:3, :3].T + T_needle[:3, 3])
    else:  # not localised yet: it may hang a whole needle diameter below the jaw
        low = [T_now[:3, 3] - 2.0 * ctx.needle.radius * up]
    # An uncalibrated arm's tip may be off by what the task's offset bound allows.
    rise = MIN_CLEARANCE + tip_margin(arm)
    rise -= float(np.min((np.array(low) @ up)[:, None] - ports @ up))
    if rise <= 0.0:
        return [T_goal]
    for part in (1.0, 0.75, 0.5, 0.25):  # as high as the arm can, if not all the way
        T_up = T_now.copy()
        T_up[:3, 3] += part * rise * up
        if not feasible(arm, [T_up]):
            return [T_up, T_goal]
    return [T_goal]

