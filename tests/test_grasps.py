"""Grasp hands: the needle point at the arc angle sits on the jaw's pinch point, across the jaws."""

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.planning import plan_needle_arc
from suture_bt.sim.grasp import check_grasp
from suture_bt.skills.grasps import (
    END_MARGIN,
    GRASP_DEPTH,
    backed_off,
    free_angle,
    hand,
    held_arc_angle,
    insertion_grasp_angle,
    tip_goal,
)
from suture_bt.transforms import invert, make_transform, pose_to_transform, rpy_to_matrix

NEEDLE = NeedleModel()
LO, HI = NEEDLE.tip_angle + END_MARGIN, NEEDLE.base_angle - END_MARGIN
ANGLES = list(np.linspace(LO, HI, 6))
PINCH = np.array([0.0, 0.0, -GRASP_DEPTH])


def _needle_poses():
    rng = np.random.default_rng(7)
    poses = [np.eye(4)]
    for _ in range(3):
        poses.append(
            make_transform(rpy_to_matrix(rng.uniform(-np.pi, np.pi, 3)), rng.uniform(-0.05, 0.1, 3))
        )
    return poses


@pytest.mark.parametrize("pulling", [False, True])
@pytest.mark.parametrize("a", ANGLES)
def test_hand_puts_arc_point_on_pinch_point(a, pulling):
    T = hand(NEEDLE, a, pulling=pulling)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    p_tip = T[:3, :3] @ NEEDLE.point_at(a) + T[:3, 3]
    np.testing.assert_allclose(p_tip, PINCH, atol=1e-12)
    np.testing.assert_allclose(T[:3, 2], [0.0, 0.0, -1.0], atol=1e-12)  # needle z = −tip z
    wire = T[:3, :3] @ NEEDLE.tangent_at(a)
    np.testing.assert_allclose(np.abs(wire), [1.0, 0.0, 0.0], atol=1e-12)  # wire along tip x


@pytest.mark.parametrize("a", ANGLES)
def test_pulling_hand_is_driving_hand_turned_about_tip_z(a):
    drive, pull = hand(NEEDLE, a), hand(NEEDLE, a, pulling=True)
    Rz_pi = make_transform(rpy_to_matrix((0.0, 0.0, np.pi)))
    # Turning the tip frame half a turn about its own z keeps the pinch point (on tip z).
    np.testing.assert_allclose(pull, Rz_pi @ drive, atol=1e-12)
    # The driving tip travels toward −tip x (the wire's direction of travel).
    np.testing.assert_allclose(drive[:3, :3] @ NEEDLE.tangent_at(a), [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(pull[:3, :3] @ NEEDLE.tangent_at(a), [1, 0, 0], atol=1e-12)
    # Arc centre in the tip frame: −tip y for the driving hand, +tip y for the pulling one
    # (the module docstring says "+tip y" for the driving hand; the code, like the sim's
    # in-jaw pose, puts it at −tip y).
    np.testing.assert_allclose(drive[:3, 3], [0, -NEEDLE.radius, -GRASP_DEPTH], atol=1e-12)
    np.testing.assert_allclose(pull[:3, 3], [0, NEEDLE.radius, -GRASP_DEPTH], atol=1e-12)


@pytest.mark.parametrize("pulling", [False, True])
@pytest.mark.parametrize("a", ANGLES)
def test_tip_goal_grasps_in_simulation_geometry(a, pulling):
    T_hand = hand(NEEDLE, a, pulling=pulling)
    for T_needle in _needle_poses():
        T_tip = tip_goal(T_needle, T_hand)
        np.testing.assert_allclose(T_tip @ T_hand, T_needle, atol=1e-12)
        g = check_grasp(T_tip, 0.0, T_needle, NEEDLE)
        assert g.ok, g.reason
        assert g.arc_angle == pytest.approx(a, abs=1e-3)
        np.testing.assert_allclose(g.T_tip_needle, T_hand, atol=1e-9)


def test_tip_goal_off_the_wire_does_not_grasp():
    """The grasp check is not fooled: a goal 3 mm beside the wire is rejected."""
    T_needle = _needle_poses()[2]
    T_tip = tip_goal(T_needle, hand(NEEDLE, 2.0))
    T_tip[:3, 3] += 0.003 * T_tip[:3, 1]
    assert not check_grasp(T_tip, 0.0, T_needle, NEEDLE).ok


@pytest.mark.parametrize("pulling", [False, True])
@pytest.mark.parametrize("a", ANGLES)
def test_held_arc_angle_inverts_hand(a, pulling):
    assert held_arc_angle(NEEDLE, hand(NEEDLE, a, pulling=pulling)) == pytest.approx(a, abs=1e-9)


def test_held_arc_angle_with_small_slip():
    T = hand(NEEDLE, 2.2)
    T_slip = make_transform(None, (0.0003, 0.0, 0.0)) @ T  # 0.3 mm along the wire
    assert held_arc_angle(NEEDLE, T_slip) == pytest.approx(2.2, abs=0.3e-3 / NEEDLE.radius * 1.1)


def test_held_arc_angle_is_clipped_to_the_needle():
    assert held_arc_angle(NEEDLE, hand(NEEDLE, NEEDLE.tip_angle - 0.3)) == NEEDLE.tip_angle
    assert held_arc_angle(NEEDLE, hand(NEEDLE, NEEDLE.base_angle + 0.3)) == NEEDLE.base_angle


@pytest.mark.parametrize("a", [-0.3, -0.9, NEEDLE.base_angle + 2.3])
def test_held_arc_angle_past_the_tip_across_angle_zero_is_the_tip(a):
    # the off-arc gap spans angle zero: the nearer end is found around the circle
    assert held_arc_angle(NEEDLE, hand(NEEDLE, a)) == NEEDLE.tip_angle


@pytest.mark.parametrize("a", [NEEDLE.base_angle + 1.5, NEEDLE.base_angle + 1.9])
def test_held_arc_angle_far_past_the_base_is_the_base(a):
    assert held_arc_angle(NEEDLE, hand(NEEDLE, a)) == NEEDLE.base_angle


@pytest.mark.parametrize(
    "T_phantom",
    [np.eye(4), pose_to_transform((0.03, -0.02, 0.0), (0.0, 0.0, 0.26))],
    ids=["default", "moved"],
)
@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_insertion_grasp_angle_passes_the_planner(T_phantom, pair):
    arc = plan_needle_arc(*PhantomModel(T_phantom).pair(pair), NEEDLE)
    a = insertion_grasp_angle(arc)
    assert LO <= a <= HI
    arc.check_grasp(hand(NEEDLE, a), 0.0015)  # raises NeedleArcError when it fails
    # and it leaves the planner's limit with a margin
    assert arc.grasp_limit_angle(hand(NEEDLE, a), 0.0015) > arc.insert_end_angle


def test_free_angle_without_avoid_is_mid_arc():
    assert free_angle(NEEDLE, []) == pytest.approx(0.5 * (LO + HI))


@pytest.mark.parametrize(
    "avoid",
    [[2.0], [1.2], [HI], [2.0, 2.8], [1.3, 2.0, 2.9], [0.2], [4.0], [1.5, 1.6]],
)
def test_free_angle_maximises_gap_within_margins(avoid):
    a = free_angle(NEEDLE, avoid)
    assert LO - 1e-12 <= a <= HI + 1e-12
    grid = np.linspace(LO, HI, 20001)
    best = np.max(np.min(np.abs(grid[:, None] - np.asarray(avoid)[None]), axis=1))
    gap = min(abs(a - v) for v in avoid)
    assert gap >= best - (HI - LO) / 199 - 1e-12


def test_free_angle_two_avoided_picks_the_widest_gap():
    # Avoid the tip-side end and the middle: the base-side end is farthest from both.
    a = free_angle(NEEDLE, [LO, 0.5 * (LO + HI) - 0.1])
    assert a == pytest.approx(HI)


@pytest.mark.parametrize("d", [0.0, 0.005, 0.012])
def test_backed_off_moves_along_minus_tip_z(d):
    T = make_transform(rpy_to_matrix((0.4, -0.9, 2.3)), (0.01, 0.04, 0.07))
    T_copy = T.copy()
    B = backed_off(T, d)
    np.testing.assert_array_equal(T, T_copy)  # input untouched
    np.testing.assert_allclose(B[:3, :3], T[:3, :3], atol=0)
    np.testing.assert_allclose(B[:3, 3], T[:3, 3] - d * T[:3, 2], atol=1e-15)
    # In the original tip frame the new origin is at (0, 0, −d).
    np.testing.assert_allclose((invert(T) @ B)[:3, 3], [0.0, 0.0, -d], atol=1e-15)
