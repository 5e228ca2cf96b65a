"""Presentation poses: pinch points in view, reachable jaw poses, the needle clear of the tissue."""

import numpy as np
import pytest
from skill_helpers import CAMERA, PHANTOMS, make_arm, make_ctx

from suture_bt.calibration.calibration_pose import offset_box_points
from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.kinematics import forward_kinematics, inverse_kinematics
from suture_bt.planning import to_base
from suture_bt.skills.context import NeedleBelief
from suture_bt.skills.grasps import GRASP_DEPTH, hand
from suture_bt.skills.held_needle import needle_places
from suture_bt.skills.presentation import (
    DEPTH,
    DEPTHS,
    DIRECTIONS,
    FACE_ON_WORTH,
    LEVEL_TILTS_DEG,
    MIN_CLEARANCE,
    MIN_NEEDLE_CLEARANCE,
    NEAR_DEPTHS,
    candidate_poses,
    face_on,
    iter_candidates,
    lifted_first,
    needle_clearance,
    presentation_point,
    presentation_points,
)
from suture_bt.skills.tip_uncertainty import worst_offset_displacement
from suture_bt.transforms import make_transform


def clearance(ctx, p) -> float:
    up = ctx.phantom.T_world_phantom[:3, 2]
    return float(min((p - port.position) @ up for port in ctx.phantom.ports()))


def pinch(T):
    return (T @ np.array([0.0, 0.0, -GRASP_DEPTH, 1.0]))[:3]


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_presentation_points_start_at_the_image_centre_and_stay_in_view(phantom):
    ctx = make_ctx(PHANTOMS[phantom])
    points = presentation_points(ctx)
    left = CAMERA.model.left
    assert left.to_camera(points[0][None])[0] == pytest.approx([0.0, 0.0, DEPTH], abs=1e-12)
    np.testing.assert_allclose(presentation_point(ctx), points[0])
    for cam in (CAMERA.model.left, CAMERA.model.right):
        uv = cam.project(np.array(points))
        assert np.all((uv >= 0) & (uv < [cam.width, cam.height]))


def test_the_arms_own_side_comes_first_at_equal_distance():
    ctx = make_ctx()
    for side in (1.0, -1.0):
        xs = [CAMERA.model.left.to_camera(p[None])[0][0] for p in presentation_points(ctx, side)]
        first_off_centre = next(x for x in xs if abs(x) > 1e-9)
        assert np.sign(first_off_centre) == side


@pytest.mark.parametrize("arm_name", ["psm2", "psm1"])
@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_candidate_poses_reachable_with_the_pinch_on_a_grid_point(phantom, arm_name):
    ctx = make_ctx(PHANTOMS[phantom])
    arm = make_arm(arm_name)
    cands = candidate_poses(ctx, arm, limit=8)
    assert len(cands) > 0
    grid = np.array(
        [
            p
            for side in (1.0, -1.0)
            for d in (DEPTHS, NEAR_DEPTHS)
            for p in presentation_points(ctx, side, d)
        ]
    )
    base = arm.base_frame()
    for T in cands:
        np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
        assert np.min(np.linalg.norm(grid - pinch(T), axis=1)) < 1e-12
        q = inverse_kinematics(to_base(T, base), arm.servo.setpoint_jp())
        np.testing.assert_allclose(base @ forward_kinematics(q), T, atol=1e-9)


@pytest.mark.parametrize("arm_name", ["psm2", "psm1"])
def test_candidate_jaw_axes_are_the_listed_directions(arm_name):
    """Every jaw axis looks into the scene, no farther from the line of sight than the widest
    of DIRECTIONS (54.7°, for (−1, −1, 1))."""
    widest = max(np.arccos(d[2] / np.linalg.norm(d)) for d in DIRECTIONS)
    axis = CAMERA.model.left.T_world_cam[:3, 2]
    for T in candidate_poses(make_ctx(), make_arm(arm_name), limit=8):
        assert np.arccos(np.clip(T[:3, 2] @ axis, -1, 1)) <= widest + 1e-9


@pytest.mark.parametrize("phantom", ["default", "moved"])
def test_an_uncalibrated_arm_presents_where_no_offset_in_the_bound_puts_the_needle_in_tissue(
    phantom,
):
    """The Task 3 start: the grasp unknown, the arm not calibrated. For the first candidates,
    the needle's whole circle on either side of the jaw, with the arm driven by offsets over
    the bound box (FK of the true joints), stays above the known tissue surface."""
    ctx = make_ctx(PHANTOMS[phantom])
    arm = make_arm("psm2")
    base = arm.base_frame()
    cands = candidate_poses(ctx, arm, limit=5)
    assert len(cands) == 5
    for T in cands:
        assert needle_clearance(ctx, arm, T) >= MIN_NEEDLE_CLEARANCE
        q = inverse_kinematics(to_base(T, base), arm.servo.setpoint_jp())
        T_tip_needle_places = np.linalg.inv(T)
        for dq in offset_box_points(3):
            q_true = q.copy()
            q_true[:3] += dq
            T_true = base @ forward_kinematics(q_true)
            places = needle_places(ctx, arm, T)  # where the needle may be at the planned pose
            moved = places @ (T_true @ T_tip_needle_places)[:3, :3].T
            moved += (T_true @ T_tip_needle_places)[:3, 3]
            assert np.min(height_above_tissue(ctx.phantom, moved)) > 0.0


def test_the_uncalibrated_presentations_go_higher_than_the_calibrated_ones():
    ctx = make_ctx()
    calibrated, uncalibrated = make_arm("psm2"), make_arm("psm2")
    calibrated.calibrated = True
    up = ctx.phantom.T_world_phantom[:3, 2]
    high = pinch(candidate_poses(ctx, uncalibrated, limit=1)[0]) @ up
    low = pinch(candidate_poses(ctx, calibrated, limit=1)[0]) @ up
    assert high > low + 0.005  # about 10 mm at the Task 3 start


def test_a_presentation_that_may_put_the_needle_into_the_tissue_goes_last():
    ctx = make_ctx(make_transform(None, (0.0, 0.0, 0.01)))  # the phantom 10 mm higher
    arm = make_arm("psm2")
    arm.calibrated = True
    clear = [needle_clearance(ctx, arm, T) for T in candidate_poses(ctx, arm, limit=2000)]
    ok = [c >= MIN_NEEDLE_CLEARANCE for c in clear]
    assert any(ok) and not all(ok)
    assert all(a >= b for a, b in zip(ok, ok[1:], strict=False))  # every clear one first
    poses = candidate_poses(ctx, arm, limit=2000)
    unsafe = [
        c + FACE_ON_WORTH * face_on(ctx, arm, T)
        for c, k, T in zip(clear, ok, poses, strict=True)
        if not k
    ]
    # Highest first, a pose that faces the cameras counted FACE_ON_WORTH higher.
    assert all(a >= b - 1e-9 for a, b in zip(unsafe, unsafe[1:], strict=False))


def test_nearer_points_only_when_no_usual_point_is_safe_for_the_arms_own_presentation():
    """The phantom 8 mm higher: no pinch point at the usual distances is safe for an
    uncalibrated PSM2 (every offset in the bound considered), so its own presentation goes
    nearer the cameras, where the pinch point stands higher; a presentation toward the other
    arm (a handover) keeps to the usual distances (none here); the default scene is unchanged."""
    arm = make_arm("psm2")
    raised = make_ctx(make_transform(None, (0.0, 0.0, 0.008)))
    cands = candidate_poses(raised, arm, limit=4)
    assert cands
    for T in cands:
        depth = CAMERA.model.left.to_camera(pinch(T)[None])[0][2]
        assert min(abs(depth - d) for d in NEAR_DEPTHS) < 1e-9
        assert needle_clearance(raised, arm, T) >= MIN_NEEDLE_CLEARANCE
    assert not list(iter_candidates(raised, arm, toward=make_arm("psm1")))
    usual = make_ctx()
    for T in candidate_poses(usual, arm, limit=24):
        depth = CAMERA.model.left.to_camera(pinch(T)[None])[0][2]
        assert min(abs(depth - d) for d in DEPTHS) < 1e-9


def test_a_needle_of_unknown_pose_faces_the_cameras_as_the_jaw_axis_says():
    """Unknown in-hand pose: the plane is across the jaws whatever the arc angle, so a jaw
    pointing along the line of sight faces the cameras and one across it does not."""
    ctx = make_ctx()
    arm = make_arm("psm2")
    cam = ctx.camera.model.left.T_world_cam
    point = cam[:3, 3] + 0.06 * cam[:3, 2]
    along = make_transform(cam[:3, :3], point)
    across = make_transform(cam[:3, :3] @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]), point)
    assert face_on(ctx, arm, along) and not face_on(ctx, arm, across)


def test_level_jaw_axes_are_among_the_orientations():
    from suture_bt.skills.presentation import _orientations

    ctx = make_ctx()
    down = -ctx.phantom.T_world_phantom[:3, 2]
    tilts = [np.degrees(np.arccos(np.clip(R[:, 2] @ down, -1, 1))) for R in _orientations(ctx, 1.0)]
    for t in LEVEL_TILTS_DEG:
        assert min(abs(np.array(tilts) - t)) < 1e-6


def test_a_known_grasp_is_judged_by_its_arc():
    ctx = make_ctx()
    arm = make_arm("psm2")
    arm.calibrated = True
    T = candidate_poses(ctx, arm, limit=1)[0]
    unknown = needle_clearance(ctx, arm, T)
    ctx.belief = NeedleBelief(np.eye(4), 0.0, "test", "psm2", hand(ctx.needle, np.deg2rad(155)))
    arc = needle_places(ctx, arm, T)
    assert len(arc) == 9
    assert np.linalg.norm(arc - pinch(T), axis=1).max() <= 2 * ctx.needle.radius + 1e-9
    # The arc is part of the circle (sampled at 16 points: its lowest point may lie up to
    # r·(1 − cos(π/16)) = 0.2 mm below the lowest sample).
    assert needle_clearance(ctx, arm, T) >= unknown - 2e-4


def test_candidate_poses_do_not_command_the_arm():
    arm = make_arm("psm2")
    candidate_poses(make_ctx(), arm)
    assert arm.arm.commands == [] and arm.servo.desired is None


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_a_low_tip_rises_straight_up_before_it_is_presented(phantom):
    ctx = make_ctx(PHANTOMS[phantom])
    arm = make_arm("psm2")  # at the Task 3 start pose, the needle 10-16 mm above the entries
    arm.calibrated = True  # (the margin of an uncalibrated arm: see below)
    ctx.belief = NeedleBelief(np.eye(4), 0.0, "test", "psm2", hand(ctx.needle, np.deg2rad(155)))
    goal = candidate_poses(ctx, arm)[0]
    up_first, final = lifted_first(ctx, arm, goal)
    T_now = arm.commanded_tip_world()
    rise = up_first[:3, 3] - T_now[:3, 3]
    up = ctx.phantom.T_world_phantom[:3, 2]
    assert np.linalg.norm(np.cross(rise, up)) < 1e-9 and rise @ up > 0  # straight up
    T_needle = up_first @ ctx.belief.T_tip_needle  # the lowest needle point now clears
    arc = ctx.needle.point_at(np.linspace(ctx.needle.tip_angle, ctx.needle.base_angle, 9))
    pts = arc @ T_needle[:3, :3].T + T_needle[:3, 3]
    assert min(clearance(ctx, p) for p in pts) == pytest.approx(MIN_CLEARANCE, abs=1e-9)
    np.testing.assert_allclose(up_first[:3, :3], T_now[:3, :3])
    assert final is goal


def test_a_tip_already_high_goes_straight_to_the_presentation():
    ctx = make_ctx(make_transform(None, (0.0, 0.0, -0.06)))  # the phantom 60 mm lower
    arm = make_arm("psm2")
    goal = candidate_poses(ctx, arm)[0]
    assert lifted_first(ctx, arm, goal) == [goal]


def test_a_needle_not_yet_localised_is_assumed_to_hang_a_diameter_below_the_jaw():
    # At the Task 3 start the jaw is 26 mm above the ports but the needle hangs lower; with no
    # estimate yet the lift assumes the worst (a dragged needle went 15 mm into the ridge).
    ctx = make_ctx()
    arm = make_arm("psm2")
    arm.calibrated = True
    goal = candidate_poses(ctx, arm)[0]
    up_first, _ = lifted_first(ctx, arm, goal)
    assert clearance(ctx, up_first[:3, 3]) == pytest.approx(
        MIN_CLEARANCE + 2 * ctx.needle.radius, abs=1e-9
    )


def test_an_uncalibrated_arm_rises_further_by_its_worst_offset_displacement():
    ctx = make_ctx()
    calibrated, uncalibrated = make_arm("psm2"), make_arm("psm2")
    calibrated.calibrated = True
    goal = candidate_poses(ctx, calibrated)[0]
    high = lifted_first(ctx, uncalibrated, goal)[0]
    low = lifted_first(ctx, calibrated, goal)[0]
    extra = clearance(ctx, high[:3, 3]) - clearance(ctx, low[:3, 3])
    margin = worst_offset_displacement(uncalibrated.servo.estimated_jp())
    assert 0.010 < margin < 0.025  # the SRC bound at the start pose: about 18 mm
    # As high as the arm can go: all of the margin, or a quarter-step short of it.
    assert extra == pytest.approx(margin, abs=1e-9) or 0.0 < extra < margin


@pytest.mark.parametrize("calibrated", [False, True])
def test_presentations_in_a_row_differ_in_place(calibrated):
    """A refused presentation moves on to another point, not only another turn of the jaw."""
    ctx = make_ctx()
    arm = make_arm("psm2")
    arm.calibrated = calibrated
    pinches = [pinch(T) for T in candidate_poses(ctx, arm, limit=3)]
    assert np.linalg.norm(pinches[0] - pinches[1]) > 1e-3
