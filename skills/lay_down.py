"""Skill: lay a held needle down on the tissue, where it can be seen and picked up again.

How the preparation empties the jaw that holds the needle at the SRC Task 3 start: the
(uncalibrated) arm lays it flat on the tissue and lets go, so the tree can calibrate the arm
with its jaw empty and pick the needle up from the tissue (:mod:`pick_up`), which works
whatever the offsets (localising a resting needle needs no presentation; one held in an
uncalibrated jaw does). The spot is chosen from the
phantom's known frame and the camera model: on the flat tissue top beside the ridge, where a
needle lying around it is in both cameras' view and the arm can both reach the release pose
and come down on the needle from above. The jaws point straight down, so a needle held across
them (every grasp of the task) lies level with its z axis up: the pick-up's driving hand takes
it. The release height keeps the needle clear of the tissue under every tip displacement the
arm's offsets may still cause. Output: no belief (the needle lies somewhere around the spot).
"""

from __future__ import annotations

import numpy as np

from suture_bt.calibration.calibration_pose import (
    CALIBRATION_JAW,
    CALIBRATION_POSES,
    actual_joints,
    offset_box_points,
)
from suture_bt.calibration.jaw_keypoints import project_keypoints
from suture_bt.geometry.phantom import TISSUE_TOP_Z, TISSUE_X, TISSUE_Y
from suture_bt.geometry.tissue_surface import height_above_tissue, surface_height
from suture_bt.kinematics import UnreachablePoseError, inverse_kinematics
from suture_bt.planning import to_base
from suture_bt.skills import checks, presentation
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.grasps import GRASP_DEPTH, hand
from suture_bt.skills.motion import FINE, feasible, jaw_to, move_to, wait
from suture_bt.skills.recover import JAW_OPEN
from suture_bt.skills.resting_grasp import grasp_path
from suture_bt.transforms import make_transform, rpy_to_matrix

#: Spots tried (phantom frame, m: x across the ridge, y along it), beside the ridge on either
#: side (the SRC's own resting needle lies at x = -21 mm, y = 56 mm).
SPOTS_X = (-0.032, -0.027, -0.022, -0.017, 0.022, 0.027)
SPOTS_Y = (0.045, 0.030, 0.015, 0.0, -0.015, -0.030)
#: Least share of the needle's possible landing places that must be flat tissue in view.
MIN_LANDING_SHARE = 0.5
#: Landing places this close to the block's edges count as off it (m).
EDGE_MARGIN = 0.003
#: Rolls (about the downward jaw axis) tried for the release pose (rad).
ROLLS = np.deg2rad(np.arange(0.0, 360.0, 30.0))
#: Clearance of the held needle above the tissue at the release, past the offset
#: displacements (m); the fall is this plus whatever displacement did not happen.
RELEASE_CLEARANCE = 0.004
#: The arm comes to the release pose from this far above it, and rises this far after (m).
ABOVE = 0.015
#: The needle is given this long to come to rest (s).
SETTLE_S = 0.4
#: Needle orientations about the vertical (rad) of which at least ``PICK_SHARE`` must have
#: their pick-up in reach (how it lies about the vertical depends on the unknown grasp).
PICK_YAWS = np.deg2rad(np.arange(0.0, 360.0, 30.0))
PICK_SHARE = 0.75
#: The needle's possible places stay this far (px at 1080 rows) in the left image from the
#: laying arm's jaw keypoints at its calibration pose, wherever the offset bound may put them:
#: the arm calibrates next, and a needle under a keypoint takes it (a campaign trial: a jaw
#: tip found on the wire 10 px off, calibration 0.9° off, the pick-up closed empty).
JAW_VIEW_MARGIN_PX = 40.0


def calibration_jaw_pixels(ctx: TaskContext, arm: ArmHandle) -> np.ndarray:
    """Left-image pixels (N×2) of ``arm``'s jaw keypoints at its calibration pose over the
    offset bound box (none for an arm with no calibration pose)."""
    if arm.name not in CALIBRATION_POSES:
        return np.zeros((0, 2))
    q = actual_joints(CALIBRATION_POSES[arm.name], offset_box_points(3))
    px = project_keypoints(q, CALIBRATION_JAW, arm.base_frame(), ctx.camera.model.left)
    return px.reshape(-1, 2)


def _spot_frames(ctx: TaskContext) -> list[np.ndarray]:
    """Needle poses lying flat (z up) centred at each spot on the tissue top (world)."""
    T_ph = ctx.phantom.T_world_phantom
    out = []
    for x in SPOTS_X:
        for y in SPOTS_Y:
            T = np.eye(4)
            T[:3, 3] = (x, y, TISSUE_TOP_Z + ctx.needle.wire_radius)
            out.append(T_ph @ T)
    return out


def _turned(T: np.ndarray, yaw: float) -> np.ndarray:
    """``T`` turned by ``yaw`` (rad) about its own z axis."""
    return T @ make_transform(rpy_to_matrix((0.0, 0.0, yaw)))


def release_pose(ctx: TaskContext, arm: ArmHandle, T_spot: np.ndarray) -> np.ndarray | None:
    """The tip pose that lets go of the needle over ``T_spot``: jaws straight down (tip z
    against the phantom's up), the pinch point over the spot's centre offset by the needle's
    radius (the jaw holds the wire, not the centre), high enough under the arm's offsets; the
    roll nearest the arm's present one that it reaches. None when none is reachable."""
    up = ctx.phantom.T_world_phantom[:3, 2]
    q_now = arm.servo.setpoint_jp()
    best = None
    for roll in ROLLS:
        x = _turned(T_spot, roll)[:3, 0]
        y = np.cross(-up, x)
        R = np.column_stack([x, y, -up])
        # The needle lies beside the pinch, one radius along the jaw's y (the driving hand).
        pinch = T_spot[:3, 3] - ctx.needle.radius * y
        T = make_transform(R, pinch + GRASP_DEPTH * R[:, 2])  # the tip is ahead of the pinch
        try:
            q = inverse_kinematics(to_base(T, arm.base_frame()), q_now)
        except UnreachablePoseError:
            continue
        low = presentation.displacements(arm, q) @ up
        T[:3, 3] += (RELEASE_CLEARANCE + max(0.0, -float(np.min(low)))) * up
        if feasible(arm, [T]):
            continue
        turn = abs(float(np.angle(np.exp(1j * (q[3] - q_now[3])))))
        if best is None or turn < best[0]:
            best = (turn, T)
    return None if best is None else best[1]


class LayDown(Skill):
    """``arm`` lays the needle it holds on the tissue and lets go; ``arc_angle`` (rad) is the
    grasp the pick-up after it will take (its reach is checked for the spot)."""

    name = "lay down"

    def __init__(self, context: TaskContext, arm: str, arc_angle: float):
        super().__init__(context)
        self.arm_name, self.arc_angle = arm, float(arc_angle)

    def program(self) -> Waiting:
        ctx = self.context
        arm = ctx.arm(self.arm_name)
        angle = arm.jaw_angle()
        held, detail = checks.jaw_holds_wire(angle)
        if not held or angle > checks.JAW_CLOSED_MAX:
            raise SkillFailure(f"lay down: {arm.name}'s jaw holds no needle ({detail})")
        T_spot, T_release = self._choose_spot(arm)
        T_above = _above(ctx, T_release)
        self.report.update(
            spot=T_spot[:3, 3].tolist(),
            release_height_mm=float(
                1e3 * (height_above_tissue(ctx.phantom, T_release[:3, 3][None])[0])
            ),
        )
        self.say(f"{arm.name} lays the needle down at {np.round(1e3 * T_spot[:3, 3], 1)} mm")
        yield from move_to(
            ctx.clock, arm, presentation.lifted_first(ctx, arm, T_above), "go over the spot"
        )
        yield from move_to(ctx.clock, arm, [T_release], "come down to the release", FINE)
        yield from jaw_to(arm, JAW_OPEN)
        ctx.belief = None
        ctx.start_holder = None
        ctx.needle_hint = T_spot[:3, 3].copy()
        yield from move_to(ctx.clock, arm, [T_above], "rise clear of the needle", FINE)
        yield from wait(ctx.clock, SETTLE_S)
        self.say(f"{arm.name} let the needle go over the tissue")

    def _choose_spot(self, arm: ArmHandle) -> tuple[np.ndarray, np.ndarray]:
        """The spot where the needle most surely lands flat on the tissue in view: the share of
        its possible places (a circle two radii round the spot, either side of the jaw, moved
        by the tip displacements the arm's offsets may still cause) that lie on the flat top
        (not the ridge, not off the block) and in both images must be ``MIN_LANDING_SHARE``;
        spots are ranked by the share that is also not under the arm's calibration jaw in the
        left image (``JAW_VIEW_MARGIN_PX``), plus (counted once more: a needle off the block
        is lost, a fresh campaign trial's was) the share on the block; ties nearest the
        centre.
        Its release pose and the way there from where the arm is must be reachable, and the
        pick-up from at least ``PICK_SHARE`` of the needle's orientations."""
        ctx = self.context
        T_hand = hand(ctx.needle, self.arc_angle)
        cam = ctx.camera.model.left
        centre = np.array([cam.width / 2.0, cam.height / 2.0])
        ring = 2.0 * ctx.needle.point_at(np.linspace(0.0, 2 * np.pi, 12, endpoint=False))
        jaw_px = calibration_jaw_pixels(ctx, arm)
        margin = JAW_VIEW_MARGIN_PX * cam.height / 1080.0
        ranked, reasons = [], []
        for T_spot in _spot_frames(ctx):
            T_release = release_pose(ctx, arm, T_spot)
            if T_release is None:
                reasons.append("no release pose in reach")
                continue
            q = inverse_kinematics(to_base(T_release, arm.base_frame()), arm.servo.setpoint_jp())
            moved = presentation.displacements(arm, q)
            places = ring @ T_spot[:3, :3].T + T_spot[:3, 3]
            places = (places[:, None, :] + moved[None]).reshape(-1, 3)
            good = landing_ok(ctx, places)
            if np.mean(good) < MIN_LANDING_SHARE:
                reasons.append(
                    f"too little of where it may land is flat tissue in view ({np.mean(good):.0%})"
                )
                continue
            if len(jaw_px):
                px = cam.project(places)
                gap = np.min(np.linalg.norm(px[:, None] - jaw_px[None], axis=2), axis=1)
                good &= gap >= margin
            share = float(np.mean(good))
            way = presentation.lifted_first(ctx, arm, _above(ctx, T_release)) + [T_release]
            why = feasible(arm, way)
            if why:  # a fresh held-out-style trial's wrist could not turn that far on the way
                reasons.append(f"the way there out of reach ({why})")
                continue
            picks = [grasp_path(ctx, _turned(T_spot, yaw), T_hand) for yaw in PICK_YAWS]
            whys = [w for w in (feasible(arm, p) for p in picks) if w]
            if len(whys) > len(PICK_YAWS) * (1.0 - PICK_SHARE):
                reasons.append(f"pick-up out of reach ({whys[0]})")
                continue
            off_centre = float(np.linalg.norm(cam.project(T_spot[:3, 3][None])[0] - centre))
            # A needle off the block is lost: its share counts once more in the ranking.
            kept = float(np.mean(on_block(ctx, places)))
            rank = -round(share + kept, 2)
            ranked.append((rank, off_centre, len(ranked), T_spot, T_release, share, kept))
        if ranked:
            *_, T_spot, T_release, share, kept = min(ranked, key=lambda r: r[:3])
            self.report.update(landing_share=share, on_block_share=kept)
            return T_spot, T_release
        kinds = {r.split(" (")[0]: r for r in reasons}  # one example of each kind
        raise SkillFailure(
            f"lay down: no spot on the tissue where {arm.name} can lay the needle and pick it "
            f"up again ({'; '.join(kinds.values())})"
        )


def _above(ctx: TaskContext, T_release: np.ndarray) -> np.ndarray:
    """The pose ``ABOVE`` the release along the phantom's up axis (the way in and out)."""
    T = np.array(T_release, dtype=float)
    T[:3, 3] += ABOVE * ctx.phantom.T_world_phantom[:3, 2]
    return T


def on_block(ctx: TaskContext, points: np.ndarray) -> np.ndarray:
    """Per world point: over the tissue block, ``EDGE_MARGIN`` inside its edges."""
    T_inv = np.linalg.inv(ctx.phantom.T_world_phantom)
    local = points @ T_inv[:3, :3].T + T_inv[:3, 3]
    return (
        (TISSUE_X[0] + EDGE_MARGIN <= local[:, 0])
        & (local[:, 0] <= TISSUE_X[1] - EDGE_MARGIN)
        & (TISSUE_Y[0] + EDGE_MARGIN <= local[:, 1])
        & (local[:, 1] <= TISSUE_Y[1] - EDGE_MARGIN)
    )


def landing_ok(ctx: TaskContext, points: np.ndarray) -> np.ndarray:
    """Per world point on the tissue top: on the flat block (not the ridge, not past its
    edges, ``EDGE_MARGIN`` inside) and inside both images."""
    flat = surface_height(ctx.phantom, points) <= TISSUE_TOP_Z + 1e-4
    return on_block(ctx, points) & flat & presentation.seen_by_both(ctx, points)
