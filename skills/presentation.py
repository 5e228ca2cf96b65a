"""Presentation poses: where an arm holds the needle so the cameras see the whole arc.

At the SRC Task 3 start the held needle is 30-48 mm from the cameras and edge-on, where the
localiser refuses or errs; held 55-85 mm away with its plane turned toward the cameras it is
localised to about 0.1 mm / 0.5° (measured). A presentation pose puts the jaw's pinch point at
one of a grid of points in view (about ``DEPTH`` in front of the left camera, nearest the image
centre first) and turns the jaw (whose axis is the needle plane's normal) from a small set of
directions toward the line of sight.

A pose is safe when its pinch point stands ``MIN_PINCH_CLEARANCE`` above the known tissue
surface under it (the flat top and the ridge of the ports,
:mod:`suture_bt.geometry.tissue_surface`) and every place the held needle may be stays
``MIN_NEEDLE_CLEARANCE`` above it: the needle's arc as believed, or, not localised yet, the
whole circle on either side of the jaw; each moved by every tip displacement the task's offset
bound allows an uncalibrated arm (at the Task 3 start up to about 20 mm: such an arm presents
higher and beside the ridge). Safe poses that keep the needle in view under half those
displacements come first (nearest point, then those whose own shaft and clevis would not hide
the needle, then a believed needle facing the cameras, then least wrist bend), then other safe
ones, then the rest, highest first. Everything is derived from the
camera model, the port frames and the arm's joints, so a moved, rotated or tilted phantom works
the same.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from itertools import islice

import numpy as np

from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.kinematics import UnreachablePoseError, inverse_kinematics
from suture_bt.planning import to_base
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.grasps import GRASP_DEPTH
from suture_bt.skills.held_needle import clearance_at, needle_place_sets, needle_places
from suture_bt.skills.line_of_sight import hidden_by_own_tool
from suture_bt.skills.motion import feasible
from suture_bt.skills.tip_uncertainty import offset_displacements, tip_displacements, tip_margin
from suture_bt.transforms import make_transform

#: Preferred distance of the pinch point in front of the left camera (m, optical axis).
DEPTH = 0.062
#: Distances tried (m), the preferred one first.
DEPTHS = (DEPTH, 0.056, 0.068)
#: Nearer distances (m), tried for an arm's own presentation only when no point at ``DEPTHS``
#: has a safe pose: nearer the cameras the pinch point stands higher above the tissue. A
#: held-out style campaign trial (seed 8629029330: the phantom 3.6 mm higher and turned 5°)
#: had every point at ``DEPTHS`` too low over the tissue for an uncalibrated PSM2.
NEAR_DEPTHS = (0.050, 0.044)
#: Image-plane offsets of the pinch point (camera frame, m): x toward the arm's own side
#: (s = +1), y up the image when negative.
X_OFFSETS = (0.0, 0.008, -0.008, 0.016, -0.016, 0.024, 0.032, 0.040, 0.048)
Y_OFFSETS = tuple(-0.004 * k for k in range(8))
#: Smallest height of the pinch point above every port for the lift on the way
#: (:func:`lifted_first`, m).
MIN_CLEARANCE = 0.02
#: Smallest height (m) of the pinch point above the tissue under it as planned (with every
#: offset displacement: ``MIN_NEEDLE_CLEARANCE``): turning between presentations swings the
#: needle about it.
MIN_PINCH_CLEARANCE = 0.02
#: Smallest height (m) of every place the held needle may be above the tissue under it.
MIN_NEEDLE_CLEARANCE = 0.008
#: Pixels the needle's possible extent keeps from the image border, in both eyes.
VIEW_MARGIN_PX = 30
#: Share of the offset displacements under which the needle must stay in view. The tissue
#: clearance takes all of them (a stab is a failed run); a needle that is out of view is only
#: a refusal, and the next presentation is tried.
VIEW_SHARE = 0.5
#: Jaw-axis directions in the camera frame (x toward the arm's own side is s = +1; +y points
#: down the image, so (0, 1, 1) holds the needle plane nearly level).
DIRECTIONS = [
    (-1.0, 0.0, 1.0),
    (-0.5, 0.0, 1.0),
    (0.0, 0.0, 1.0),
    (0.0, -1.0, 1.0),
    (0.0, -0.5, 1.0),
    (-1.0, -1.0, 1.0),
    (-0.5, 0.5, 1.0),
    (0.0, 0.5, 1.0),
    (0.0, 1.0, 1.0),
    (-0.5, 1.0, 1.0),
]
#: Jaw axes tilted this far (deg) from straight down (the phantom's −up) toward the camera's
#: viewing direction: a needle plane nearly level. Level planes keep the needle's possible
#: places highest above the tissue, and the cameras, looking 40° from straight down, see them
#: 20-55° from face-on, where the localiser answers; the camera-frame ``DIRECTIONS`` at the
#: high, off-centre points an uncalibrated arm is left with turn the plane 66-73° from
#: face-on (measured on the default Task 3 start), where it mostly refuses or errs.
LEVEL_TILTS_DEG = (0.0, 20.0)
ROLLS = np.deg2rad(np.arange(0.0, 360.0, 45.0))
#: A held needle whose plane is turned more than this from the left camera's line of
#: sight is presented after those that face it (deg): on a full run every look at 54-66° was
#: refused (a loose pose, 33-40° spread) and every one at 22-46° answered. The plane is the
#: believed one, or, the in-hand pose unknown, the one across the jaws (every grasp of the task
#: holds the needle with its plane's normal along the tip's z axis, whatever the arc angle).
FACE_ON_DEG = 45.0
#: Among poses that are not safe under every offset displacement (an uncalibrated arm at the
#: Task 3 start has no others), one that faces the cameras goes before one that does not when
#: its needle stands no more than this much lower (m).
FACE_ON_WORTH = 0.005
#: Share of the held needle's possible places the holder's own shaft and clevis may hide
#: (:func:`~suture_bt.skills.line_of_sight.hidden_by_own_tool`) before a pose goes after those
#: that hide less: on dev trials whose presentations all failed, the true needle was 27-100 %
#: hidden behind the wrist (a needle hanging below it, the shaft coming toward the cameras),
#: and 0 % in the looks that answered.
HIDDEN_MAX = 0.15
#: How many poses :func:`choose` returns (a skill presents them in turn until one answers).
CHOSEN = 7
#: Presentation points whose poses are taken in turn (a refusal moves to the next point).
SPREAD_POINTS = 5


def _side(ctx: TaskContext, arm: ArmHandle) -> float:
    """+1 when the arm's base lies on the camera's +x side."""
    cam = ctx.camera.model.left
    return 1.0 if (cam.T_cam_world @ np.r_[arm.base_frame()[:3, 3], 1.0])[0] >= 0 else -1.0


def presentation_points(
    ctx: TaskContext, side: float = 1.0, depths: tuple[float, ...] = DEPTHS
) -> list[np.ndarray]:
    """World points for the pinch point at ``depths``, in order of preference: nearest the
    image centre and ``DEPTH`` first, the arm's own side before the other at equal distance."""
    cam = ctx.camera.model.left.T_world_cam
    grid = [(d, x, y) for d in depths for x in X_OFFSETS for y in Y_OFFSETS]
    grid.sort(key=lambda g: (np.hypot(g[1], g[2]) + 2.0 * abs(g[0] - DEPTH), -g[1]))
    return [(cam @ np.array([side * x, y, d, 1.0]))[:3] for d, x, y in grid]


def presentation_point(ctx: TaskContext) -> np.ndarray:
    """The most preferred pinch point (the image centre at ``DEPTH``)."""
    return presentation_points(ctx)[0]


def hidden_share(ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray, q: np.ndarray) -> float:
    """How much of the held needle the holder's own tool may hide at joints ``q`` (tip
    ``T_tip``): the worst of the ways it may be held (an unknown side of the jaw counts as
    hidden when either side is)."""
    base = arm.base_frame()
    return max(hidden_by_own_tool(ctx, base, q, P) for P in needle_place_sets(ctx, arm, T_tip))


def displacements(
    arm: ArmHandle, q: np.ndarray | None, offsets: np.ndarray | None = None
) -> np.ndarray:
    """World tip displacements at joints ``q`` (zero if calibrated): of ``offsets``, else of
    those the arm's looks left (:mod:`offset_evidence`), else of the offset bound's corners."""
    if offsets is None:
        offsets = getattr(arm, "possible_offsets", None)  # (a bare arm stub may lack it)
    if arm.calibrated or q is None:
        return np.zeros((1, 3))
    d = offset_displacements(q, levels=2) if offsets is None else tip_displacements(q, offsets)
    return d @ arm.base_frame()[:3, :3].T


def needle_clearance(ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray) -> float:
    """Least height (m) of the held needle above the tissue with the jaw at ``T_tip``, over its
    possible places and the tip displacements an uncalibrated arm may have there."""
    q = _ik(arm, T_tip, arm.servo.setpoint_jp())
    return clearance_at(ctx, arm, T_tip, displacements(arm, q))


def seen_by_both(
    ctx: TaskContext, points_world: np.ndarray, margin_px: float = VIEW_MARGIN_PX
) -> np.ndarray:
    """Per point: in front of both cameras and inside both images with ``margin_px`` to spare."""
    pts = np.atleast_2d(points_world)
    seen = np.ones(len(pts), bool)
    for cam in (ctx.camera.model.left, ctx.camera.model.right):
        seen &= cam.to_camera(pts)[:, 2] > 0
        uv = cam.project(pts)
        m = margin_px
        seen &= (uv[:, 0] >= m) & (uv[:, 1] >= m)
        seen &= (uv[:, 0] <= cam.width - m) & (uv[:, 1] <= cam.height - m)
    return seen


def in_view(ctx: TaskContext, points_world: np.ndarray, margin_px: float = VIEW_MARGIN_PX) -> bool:
    """Whether every point projects inside both images with ``margin_px`` to spare."""
    return bool(np.all(seen_by_both(ctx, points_world, margin_px)))


def safe_to_present(ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray) -> bool:
    """Whether the jaw at ``T_tip`` stands as a presentation must: its pinch point
    ``MIN_PINCH_CLEARANCE`` above the tissue under it and every place the held needle may be
    (with the arm's offset displacements) ``MIN_NEEDLE_CLEARANCE`` above it."""
    pinch = T_tip[:3, 3] - GRASP_DEPTH * T_tip[:3, 2]
    if height_above_tissue(ctx.phantom, pinch[None])[0] < MIN_PINCH_CLEARANCE:
        return False
    return needle_clearance(ctx, arm, T_tip) >= MIN_NEEDLE_CLEARANCE


def face_on(ctx: TaskContext, arm: ArmHandle, T_tip: np.ndarray) -> bool:
    """Whether the needle at this jaw pose faces the left camera within ``FACE_ON_DEG``: the
    believed needle, or, its in-hand pose unknown, a plane across the jaws at the pinch point."""
    b = ctx.belief
    if b is None or b.holder != arm.name or b.T_tip_needle is None:
        centre, normal = T_tip[:3, 3] - GRASP_DEPTH * T_tip[:3, 2], T_tip[:3, 2]
    else:
        T_needle = T_tip @ b.T_tip_needle
        centre, normal = T_needle[:3, 3], T_needle[:3, 2]
    ray = centre - ctx.camera.model.left.T_world_cam[:3, 3]
    cos = abs(float(normal @ ray)) / float(np.linalg.norm(ray))
    return bool(np.degrees(np.arccos(min(cos, 1.0))) <= FACE_ON_DEG)


def _ik(arm: ArmHandle, T_world_tip: np.ndarray, q_near: np.ndarray) -> np.ndarray | None:
    try:
        return inverse_kinematics(to_base(T_world_tip, arm.base_frame()), q_near)
    except UnreachablePoseError:
        return None


def _orientations(ctx: TaskContext, s: float) -> list[np.ndarray]:
    """Jaw frames (rotation only): each direction (``DIRECTIONS`` in the camera frame, then
    the level ones of ``LEVEL_TILTS_DEG``), turned about its axis by each roll."""
    cam_R = ctx.camera.model.left.T_world_cam[:3, :3]
    axes = [cam_R @ (np.array([s * d[0], d[1], d[2]]) / np.linalg.norm(d)) for d in DIRECTIONS]
    down = -ctx.phantom.T_world_phantom[:3, 2]
    toward = cam_R[:, 2] - (cam_R[:, 2] @ down) * down  # the viewing direction, level part
    if np.linalg.norm(toward) > 1e-6:
        toward /= np.linalg.norm(toward)
        for t in np.deg2rad(LEVEL_TILTS_DEG):
            axes.append(np.cos(t) * down + np.sin(t) * toward)
    frames = []
    for z in axes:
        a = np.cross(z, cam_R[:, 1])
        a /= np.linalg.norm(a)
        b = np.cross(z, a)
        for roll in ROLLS:
            x = np.cos(roll) * a + np.sin(roll) * b
            frames.append(np.column_stack([x, np.cross(z, x), z]))
    return frames


def _safe_by_point(
    ctx: TaskContext,
    arm: ArmHandle,
    toward: ArmHandle | None,
    later: list,
    depths: tuple[float, ...] = DEPTHS,
) -> Iterator[tuple[bool, list[np.ndarray]]]:
    """Per presentation point (at ``depths``) in order: whether a safe pose there keeps the
    needle in view under ``VIEW_SHARE`` of the offset displacements, and its safe poses (those
    first, then those in view only as planned; each least wrist bend first). Poses that are
    not safe go to ``later`` as (-clearance, pose)."""
    s = _side(ctx, arm)
    q_now = arm.servo.setpoint_jp()
    frames = _orientations(ctx, s)
    offsets = getattr(arm, "possible_offsets", None)  # what the looks left (None: the bound)
    for point in presentation_points(ctx, _side(ctx, toward or arm), depths):
        shaft = None  # joints near this point: the offset displacements there
        best, seen_as_planned = [], []
        for R in frames:
            T = make_transform(R, point + GRASP_DEPTH * R[:, 2])
            if shaft is None:
                shaft = _ik(arm, T, q_now)
                if shaft is None:
                    continue
                d_shaft = displacements(arm, shaft, offsets)
                jaw = height_above_tissue(ctx.phantom, point + d_shaft)
                if jaw[0] < MIN_PINCH_CLEARANCE or np.min(jaw) < MIN_NEEDLE_CLEARANCE:
                    break  # the jaw too low here, however it is turned
            places = needle_places(ctx, arm, T)
            if not in_view(ctx, places):
                continue
            clear = clearance_at(ctx, arm, T, d_shaft)
            if clear < MIN_NEEDLE_CLEARANCE:
                later.append((-clear, T))
                continue
            q = _ik(arm, T, q_now)
            if q is None:
                continue
            # The corners again at the pose's own joints; a grid a look left, as at the shaft.
            d = d_shaft if offsets is not None else displacements(arm, q)
            wrist = abs(q[4]) + abs(q[5]) + 0.3 * abs(q[3] - q_now[3])
            hidden = hidden_share(ctx, arm, T, q) > HIDDEN_MAX
            bend = (hidden, not face_on(ctx, arm, T), wrist, len(best), T)
            if clearance_at(ctx, arm, T, d) < MIN_NEEDLE_CLEARANCE:
                later.append((-clear, T))
            elif not in_view(ctx, (places[:, None, :] + VIEW_SHARE * d).reshape(-1, 3)):
                seen_as_planned.append(bend)
            else:
                best.append(bend)
        yield (
            bool(best),
            [T for *_, T in sorted(best, key=lambda c: c[:4])]
            + [T for *_, T in sorted(seen_as_planned, key=lambda c: c[:4])],
        )


def iter_candidates(
    ctx: TaskContext,
    arm: ArmHandle,
    toward: ArmHandle | None = None,
) -> Iterator[np.ndarray]:
    """Reachable presentation tip poses. The safe ones (those in view under ``VIEW_SHARE`` of
    the offset displacements before those in view only as planned, then least wrist bend)
    taken in turn from the ``SPREAD_POINTS`` nearest points that have any (those with a pose
    in view under the share first), so that
    presentations refused in a row differ in place as well as in turn; then those of the
    further points; then, for the arm's own presentation (no ``toward``) when none of these
    was safe, the safe ones at ``NEAR_DEPTHS``; then the others, highest first. Points on
    ``toward``'s side of the image (default: the arm's own) come first at equal distance from
    the centre. An uncalibrated
    arm's displacements are those of the offsets its looks left (``possible_offsets``), else
    of the whole bound."""
    later: list[tuple[float, np.ndarray]] = []
    scan = _safe_by_point(ctx, arm, toward, later)
    groups = []
    for seen, group in scan:
        if group:
            groups.append((not seen, len(groups), group))
        if len(groups) >= SPREAD_POINTS:
            break
    groups = [g for *_, g in sorted(groups, key=lambda g: g[:2])]  # kept in view first
    for k in range(max((len(g) for g in groups), default=0)):
        for g in groups:
            if k < len(g):
                yield g[k]
    any_safe = bool(groups)
    for _, group in scan:
        any_safe = any_safe or bool(group)
        yield from group
    if not any_safe and toward is None:
        for _, group in _safe_by_point(ctx, arm, None, [], NEAR_DEPTHS):
            yield from group
    later.sort(key=lambda c: c[0] + FACE_ON_WORTH * (not face_on(ctx, arm, c[1])))
    q_now = arm.servo.setpoint_jp()
    for _, T in later:
        if _ik(arm, T, q_now) is not None:
            yield T


def untried(poses: list[np.ndarray], tried: list[np.ndarray], tol: float = 1e-3) -> list:
    """The ``poses`` whose tips are farther than ``tol`` (m) from every pose in ``tried``."""
    return [P for P in poses if all(np.linalg.norm(P[:3, 3] - Q[:3, 3]) > tol for Q in tried)]


def candidate_poses(ctx: TaskContext, arm: ArmHandle, limit: int = 24) -> list[np.ndarray]:
    """The first ``limit`` presentation poses of :func:`iter_candidates`."""
    return list(islice(iter_candidates(ctx, arm), limit))


def choose(
    ctx: TaskContext,
    arm: ArmHandle,
    accept: Callable[[np.ndarray], str] | None = None,
    toward: ArmHandle | None = None,
) -> tuple[list[np.ndarray], list[str]]:
    """Candidate poses the arm can move to now (and that ``accept`` passes: '' = ok), in order,
    plus the reasons the others were dropped (``toward``: see :func:`iter_candidates`)."""
    good, why = [], []
    for T in iter_candidates(ctx, arm, toward):
        reason = feasible(arm, [T]) or (accept(T) if accept else "")
        if reason:
            why.append(reason)
        else:
            good.append(T)
        if len(good) >= CHOSEN:
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
