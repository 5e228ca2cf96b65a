"""Presentation poses: a pinch point in view at DEPTH, above the ports, reachable jaw poses."""

from types import SimpleNamespace

import numpy as np
import pytest

from suture_bt.control import PIServo
from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.kinematics import forward_kinematics, inverse_kinematics
from suture_bt.planning import to_base
from suture_bt.sim.camera import stereo_model
from suture_bt.sim.world import psm_base_frame
from suture_bt.skills.context import ArmHandle, NeedleBelief
from suture_bt.skills.grasps import GRASP_DEPTH, hand
from suture_bt.skills.presentation import (
    DEPTH,
    DIRECTIONS,
    MIN_CLEARANCE,
    MIN_NEEDLE_CLEARANCE,
    candidate_poses,
    lifted_first,
    needle_clearance,
    presentation_point,
)
from suture_bt.skills.tip_uncertainty import worst_offset_displacement
from suture_bt.transforms import make_transform, pose_to_transform

#: The scene's initial joints (sim/default_scene.yaml).
INITIAL_JP = {
    "psm1": (0.4, -0.22, 0.139, 1.64, -0.37, 0.11),
    "psm2": (-0.4, -0.22, 0.139, -1.64, -0.37, -0.11),
}
CAMERA = SimpleNamespace(model=stereo_model(1920, 1080))
PHANTOMS = {
    "default": np.eye(4),
    "moved": pose_to_transform((0.03, -0.02, 0.0), (0.0, 0.0, 0.26)),
    "tilted": pose_to_transform((0.0, 0.01, 0.0), (0.2, 0.1, 0.0)),
}


class FakeArm:
    """Measured joints fixed at the scene's initial pose; servo commands are recorded."""

    def __init__(self, name: str):
        self.name = name
        self.q = np.array(INITIAL_JP[name])
        self.commands = []

    def base_frame(self) -> np.ndarray:
        return psm_base_frame(self.name)

    def measured_jp(self) -> np.ndarray:
        return self.q.copy()

    def servo_jp(self, jp) -> None:
        self.commands.append(np.asarray(jp))


def make_ctx(T_world_phantom=None):
    return SimpleNamespace(
        camera=CAMERA,
        phantom=PhantomModel(np.eye(4) if T_world_phantom is None else T_world_phantom),
        needle=NeedleModel(),
        belief=None,
    )


def make_arm(name: str = "psm2") -> ArmHandle:
    fake = FakeArm(name)
    return ArmHandle(name, fake, PIServo(fake))


def clearance(ctx, p) -> float:
    up = ctx.phantom.T_world_phantom[:3, 2]
    return float(min((p - port.position) @ up for port in ctx.phantom.ports()))


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_presentation_point_in_view_at_depth_and_clear(phantom):
    ctx = make_ctx(PHANTOMS[phantom])
    p = presentation_point(ctx)
    left = CAMERA.model.left
    pc = left.to_camera(p[None])[0]
    assert pc[2] == pytest.approx(DEPTH, abs=1e-12)  # DEPTH along the optical axis
    for cam in (CAMERA.model.left, CAMERA.model.right):
        u, v = cam.project(p[None])[0]
        assert 0 <= u < cam.width and 0 <= v < cam.height
    assert clearance(ctx, p) >= MIN_CLEARANCE


def test_presentation_point_is_nearest_the_centre_that_clears():
    """Offsets are tried from the image centre up: the first one clear enough is taken."""
    ctx = make_ctx()
    p = presentation_point(ctx)
    lower = p + CAMERA.model.left.T_world_cam[:3, 1] * 0.004  # one offset step lower (+y down)
    assert clearance(ctx, lower) < MIN_CLEARANCE <= clearance(ctx, p)


def test_raised_phantom_raises_the_point():
    low, high = make_ctx(), make_ctx(make_transform(None, (0.0, 0.0, 0.015)))
    p_low, p_high = presentation_point(low), presentation_point(high)
    assert clearance(high, p_high) > clearance(high, p_low)


@pytest.mark.xfail(
    strict=True,
    reason="presentation_point silently returns its best offset when none clears the ports "
    "by MIN_CLEARANCE: for the phantom raised 15 mm the point is only ≈9.3 mm above the "
    "ports (and below them for 30 mm), with nothing telling the caller",
)
@pytest.mark.parametrize("raise_m", [0.015, 0.030])
def test_presentation_point_clear_of_raised_phantom(raise_m):
    ctx = make_ctx(make_transform(None, (0.0, 0.0, raise_m)))
    assert clearance(ctx, presentation_point(ctx)) >= MIN_CLEARANCE


@pytest.mark.parametrize("arm_name", ["psm2", "psm1"])
@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_candidate_poses_reachable_and_pinch_at_point(phantom, arm_name):
    ctx = make_ctx(PHANTOMS[phantom])
    arm = make_arm(arm_name)
    cands = candidate_poses(ctx, arm)
    assert len(cands) > 0
    p = presentation_point(ctx)
    base = arm.base_frame()
    for T in cands:
        np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
        pinch = (T @ np.array([0.0, 0.0, -GRASP_DEPTH, 1.0]))[:3]
        np.testing.assert_allclose(pinch, p, atol=1e-12)
        q = inverse_kinematics(to_base(T, base), arm.servo.setpoint_jp())
        np.testing.assert_allclose(base @ forward_kinematics(q), T, atol=1e-9)


@pytest.mark.parametrize("arm_name", ["psm2", "psm1"])
def test_candidate_jaw_axes_are_the_listed_directions(arm_name):
    """Every jaw axis looks into the scene, no farther from the line of sight than the widest
    of DIRECTIONS (54.7°, for (−1, −1, 1))."""
    widest = max(np.arccos(d[2] / np.linalg.norm(d)) for d in DIRECTIONS)
    axis = CAMERA.model.left.T_world_cam[:3, 2]
    for T in candidate_poses(make_ctx(), make_arm(arm_name)):
        assert np.arccos(np.clip(T[:3, 2] @ axis, -1, 1)) <= widest + 1e-9


@pytest.mark.xfail(
    strict=True,
    reason="the first candidate's jaw axis is 54.7° from the left camera's optical axis: the "
    "bend ordering puts DIRECTIONS' (−1, −1, 1) first, which is never within 50°",
)
@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_first_candidate_faces_the_camera_within_50deg(phantom):
    T = candidate_poses(make_ctx(PHANTOMS[phantom]), make_arm("psm2"))[0]
    axis = CAMERA.model.left.T_world_cam[:3, 2]
    assert np.rad2deg(np.arccos(np.clip(T[:3, 2] @ axis, -1, 1))) <= 50.0


def test_a_presentation_that_may_hang_an_unlocalised_needle_into_the_tissue_goes_last():
    ctx = make_ctx(make_transform(None, (0.0, 0.0, -0.012)))  # the phantom 12 mm lower
    arm = make_arm("psm2")
    arm.calibrated = True
    clear = [needle_clearance(ctx, arm, T) for T in candidate_poses(ctx, arm)]
    ok = [c >= MIN_NEEDLE_CLEARANCE for c in clear]
    assert any(ok) and not all(ok)
    assert all(a >= b for a, b in zip(ok, ok[1:], strict=False))  # every clear one first


def test_some_candidate_faces_the_camera_within_50deg():
    axis = CAMERA.model.left.T_world_cam[:3, 2]
    angles = [
        np.rad2deg(np.arccos(T[:3, 2] @ axis))
        for T in candidate_poses(make_ctx(), make_arm("psm2"))
    ]
    assert min(angles) <= 50.0


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

