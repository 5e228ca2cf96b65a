"""A second view of a needle held by an uncalibrated arm: turn the wrist, look again, agree.

Before calibration a held needle's estimate passes only a loose held-by test (the tip may be
off by ~10 mm), and the localiser's confident wrong answers are mirror twins 17-24 mm and
130-170° off (measured on dev trials: the taker then closed on air). A turn of the wrist alone
(joints 4-6, which carry no hidden offset) moves the needle by a motion the arm's kinematics
predicts almost exactly whatever the offset on joints 1-3: the needle seen after the turn must
be where the first estimate, carried through the measured joints, puts it — for some offset
the task allows. A twin is view-dependent: it does not survive a well-chosen turn (which ones
do, measured: ``TURNS``). Known kinematics, measured joints, the camera model and the tissue
model only; no ground truth.
"""

from __future__ import annotations

import numpy as np

from suture_bt.calibration.calibration_pose import offset_box_points
from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.kinematics import JOINT_LIMITS, forward_kinematics
from suture_bt.skills import presentation
from suture_bt.skills.checks import AGREE_ANGLE_DEG, AGREE_POSITION, pose_difference
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.offset_evidence import offset_grid
from suture_bt.transforms import invert

#: Wrist turns (rad on joints 4, 5, 6), in order of preference. Measured on dev trials at the
#: Task 3 start (PSM2, seven scenes, two of whose first answers were twins 17.7 mm / 135-152°
#: off): a wrist-yaw turn of +0.3 rad answered right in all six scenes where it was tried
#: (both twins among them); a roll of +0.35 answered in 4 of 5 when the first was right and
#: gave another twin (167-179° off: disagreement, no confirmation) when it was not; pitch
#: turns kept the twin (132-155°: it would agree with itself), and negative rolls and yaws
#: were mostly refused (loose views behind the jaw). Pitch turns are therefore not used.
TURNS = (
    (0.0, 0.0, 0.3),
    (0.35, 0.0, 0.0),
    (0.0, 0.0, -0.3),
)
#: Pixels the carried needle keeps from the image border, in both eyes.
VIEW_MARGIN_PX = 40
#: Arc samples of the carried needle.
ARC_SAMPLES = 9


def carried(
    arm: ArmHandle, q_from: np.ndarray, q_to: np.ndarray, T_needle: np.ndarray, dq: np.ndarray
) -> np.ndarray:
    """The needle held rigidly, moved from joints ``q_from`` to ``q_to`` (the servo's
    estimate: measured + Δq̂), when the offset still hidden on joints 1-3 is ``dq`` (world)."""
    a, b = np.array(q_from, dtype=float), np.array(q_to, dtype=float)
    a[:3] += dq
    b[:3] += dq
    base = arm.base_frame()
    return base @ forward_kinematics(b) @ invert(base @ forward_kinematics(a)) @ T_needle


def agree_under_some_offset(
    arm: ArmHandle,
    q_first: np.ndarray,
    q_second: np.ndarray,
    T_first: np.ndarray,
    T_second: np.ndarray,
    offsets: np.ndarray | None = None,
) -> tuple[bool, str, np.ndarray]:
    """Whether the second estimate is the first carried through the measured motion, for an
    offset among ``offsets`` (default: the arm's possible offsets, else the task's bound):
    (ok, one-line detail, the offsets that agree)."""
    if offsets is None:
        offsets = arm.possible_offsets if arm.possible_offsets is not None else offset_grid()
    diffs = [
        pose_difference(carried(arm, q_first, q_second, T_first, dq), T_second) for dq in offsets
    ]
    scores = [max(dp / AGREE_POSITION, da / AGREE_ANGLE_DEG) for dp, da in diffs]
    agreeing = [dq for dq, score in zip(offsets, scores, strict=True) if score <= 1.0]
    dp, da = diffs[int(np.argmin(scores))]
    detail = (
        f"second view {dp * 1e3:.1f} mm / {da:.1f}° from the first carried through the wrist "
        f"turn (limit {AGREE_POSITION * 1e3:.0f} mm / {AGREE_ANGLE_DEG:.0f}°)"
    )
    return bool(agreeing), detail, np.array(agreeing).reshape(-1, 3)


def _arc(ctx: TaskContext, T_needle: np.ndarray) -> np.ndarray:
    n = ctx.needle
    pts = n.point_at(np.linspace(n.tip_angle, n.base_angle, ARC_SAMPLES))
    return pts @ T_needle[:3, :3].T + T_needle[:3, 3]


def wrist_turn(
    ctx: TaskContext,
    arm: ArmHandle,
    q_now: np.ndarray,
    T_needle: np.ndarray,
    skip: int = 0,
) -> tuple[np.ndarray, int] | None:
    """Joint set-points for another view and the index of its turn: the arm's set-point with
    the first of ``TURNS[skip:]`` on the wrist that stays inside the joint limits and keeps
    the carried needle in view of both eyes and clear of the tissue however the offset bends
    its motion (None: no turn will do)."""
    q_set = arm.servo.setpoint_jp()
    corners = offset_box_points(2)
    for k in range(skip, len(TURNS)):
        turn = TURNS[k]
        q = q_set.copy()
        q[3:6] += turn
        if np.any(q < JOINT_LIMITS[:, 0]) or np.any(q > JOINT_LIMITS[:, 1]):
            continue
        q_to = q_now + (q - q_set)  # the same turn from where the arm stands
        T_to = carried(arm, q_now, q_to, T_needle, np.zeros(3))
        arc = _arc(ctx, T_to)
        if not presentation.in_view(ctx, arc, VIEW_MARGIN_PX):
            continue
        # The needle is seen where it is; only its motion depends on the offset (a little).
        moved = np.vstack([_arc(ctx, carried(arm, q_now, q_to, T_needle, dq)) for dq in corners])
        if np.min(height_above_tissue(ctx.phantom, moved)) < presentation.MIN_NEEDLE_CLEARANCE:
            continue
        return q, k
    return None
