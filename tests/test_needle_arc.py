"""Needle-arc planning: exact port passage, tissue side, overshoot, reach, grasp and timing."""

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.planning.needle_arc import (
    MIN_TIP_OUT,
    NeedleArcError,
    gripper_poses,
    in_base,
    plan_needle_arc,
)
from suture_bt.transforms import invert, make_transform, pose_to_transform, rpy_to_matrix

MOVED = PhantomModel(pose_to_transform((0.03, -0.02, 0.01), (0.0, 0.0, np.deg2rad(15.0))))
PHANTOMS = {"default": PhantomModel(), "moved": MOVED}


def in_port(port, p):
    return (invert(port.T) @ np.r_[p, 1.0])[:3]


@pytest.mark.parametrize("phantom", PHANTOMS, ids=str)
@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_ideal_tip_path_passes_through_both_ports_exactly(phantom, pair):
    entry, exit_ = PHANTOMS[phantom].pair(pair)
    arc = plan_needle_arc(entry, exit_)
    np.testing.assert_allclose(arc.tip_position(0.0), entry.position, atol=1e-12)
    np.testing.assert_allclose(arc.tip_position(arc.port_angle), exit_.position, atol=1e-12)
    # The circle has the needle radius; its plane contains both normals (SRC ports: exactly).
    for phi in np.linspace(0, arc.insert_end_angle, 7):
        assert np.linalg.norm(arc.tip_position(phi) - arc.center) == pytest.approx(0.01018)
        assert np.dot(arc.tip_position(phi) - arc.center, arc.axis) == pytest.approx(0, abs=1e-12)
    assert abs(np.dot(entry.normal, arc.axis)) < 1e-9 and abs(np.dot(exit_.normal, arc.axis)) < 1e-9


@pytest.mark.parametrize("phantom", PHANTOMS, ids=str)
def test_tip_crosses_entry_then_exit_by_the_src_sign_rule(phantom):
    for pair in range(1, 5):
        entry, exit_ = PHANTOMS[phantom].pair(pair)
        arc = plan_needle_arc(entry, exit_)
        phis = np.linspace(-0.2, arc.insert_end_angle, 2001)
        z_entry = np.array([in_port(entry, arc.tip_position(p))[2] for p in phis])
        z_exit = np.array([in_port(exit_, arc.tip_position(p))[2] for p in phis])
        # Entry: + to − once; exit: − to + once (between the ports the tip is below both).
        assert (
            np.sum(np.diff(np.sign(z_entry)) < 0) == 1
            and np.sum(np.diff(np.sign(z_entry)) > 0) == 0
        )
        assert np.sum(np.diff(np.sign(z_exit)) > 0) == 1
        inside = (phis > 1e-6) & (phis < arc.port_angle - 1e-6)
        assert np.all(z_entry[inside] < 0) and np.all(z_exit[inside] < 0)


def test_overshoot_is_the_smallest_sweep_with_the_tip_out_by_the_target():
    entry, exit_ = PhantomModel().pair(1)
    arc = plan_needle_arc(entry, exit_, margin=0.001)
    assert arc.tip_height_above_exit(arc.insert_end_angle) == pytest.approx(MIN_TIP_OUT + 0.001)
    assert arc.tip_height_above_exit(arc.insert_end_angle - 1e-3) < MIN_TIP_OUT + 0.001
    heights = [
        arc.tip_height_above_exit(p) for p in np.linspace(arc.port_angle, arc.insert_end_angle, 50)
    ]
    assert np.all(np.diff(heights) > 0)
    # Derived from geometry: a larger requirement needs a larger overshoot.
    assert plan_needle_arc(entry, exit_, min_tip_out=0.007).overshoot_angle > arc.overshoot_angle


def test_needle_rotates_about_its_own_minus_z_and_centre_stays_put():
    entry, exit_ = MOVED.pair(3)
    arc = plan_needle_arc(entry, exit_)
    T0, T1 = arc.needle_pose(0.0), arc.needle_pose(0.3)
    np.testing.assert_allclose(T0[:3, 3], T1[:3, 3], atol=1e-15)
    rel = T0[:3, :3].T @ T1[:3, :3]
    np.testing.assert_allclose(rel, rpy_to_matrix((0.0, 0.0, -0.3)), atol=1e-12)
    # The tip's velocity is the needle's own tangent direction (decreasing arc angle).
    needle = NeedleModel()
    d = arc.tip_position(1e-6) - arc.tip_position(0.0)
    np.testing.assert_allclose(
        d / np.linalg.norm(d), T0[:3, :3] @ needle.tangent_at(needle.tip_angle), atol=1e-5
    )


def test_needle_too_short_or_ports_too_far_apart_fail_with_the_reason():
    entry, exit_ = PhantomModel().pair(1)
    short = NeedleModel(tip_angle=np.deg2rad(110.0))  # 70° of arc
    with pytest.raises(NeedleArcError, match="too short"):
        plan_needle_arc(entry, exit_, short)
    with pytest.raises(NeedleArcError, match="diameter"):
        plan_needle_arc(entry, exit_, NeedleModel(radius=0.003))
    with pytest.raises(NeedleArcError, match="rises at most"):
        plan_needle_arc(entry, exit_, min_tip_out=0.03)


def test_extraction_continues_until_the_base_has_left_the_exit():
    entry, exit_ = PhantomModel().pair(2)
    arc = plan_needle_arc(entry, exit_)
    ext = arc.extraction(angular_speed=0.5, dt=0.01)
    np.testing.assert_allclose(ext.poses[0], arc.needle_pose(arc.insert_end_angle), atol=1e-12)
    np.testing.assert_allclose(ext.poses[-1], arc.needle_pose(arc.extract_end_angle), atol=1e-12)
    base = (ext.poses[-1] @ np.r_[NeedleModel().base, 1.0])[:3]
    assert in_port(exit_, base)[2] > 0  # the base end is out
    later = arc.extraction(start_angle=arc.insert_end_angle + 0.1, angular_speed=0.5, dt=0.01)
    np.testing.assert_allclose(later.poses[0], arc.needle_pose(arc.insert_end_angle + 0.1))
    np.testing.assert_allclose(later.poses[-1], ext.poses[-1], atol=1e-12)


@pytest.mark.parametrize("phi", [-0.1, 0.0, 1.0, 2.0, 3.5])
def test_the_sweep_angle_is_read_back_from_the_needle_orientation(phi):
    arc = plan_needle_arc(*MOVED.pair(3))
    found, turn = arc.sweep_angle_of(arc.needle_pose(phi)[:3, :3])
    assert found == pytest.approx(phi, abs=1e-9) and turn == pytest.approx(0.0, abs=1e-6)
    tilt = make_transform(rpy_to_matrix((np.deg2rad(4.0), 0.0, 0.0)), np.zeros(3))
    found, turn = arc.sweep_angle_of((arc.needle_pose(phi) @ tilt)[:3, :3])
    assert found == pytest.approx(phi, abs=1e-3) and np.rad2deg(turn) == pytest.approx(4.0, abs=0.1)


def test_timed_sweep_respects_the_angular_limits():
    arc = plan_needle_arc(*PhantomModel().pair(4))
    ins = arc.insertion(angular_speed=0.4, angular_acc=2.0, dt=0.005)
    phis = []
    for T in ins.poses:
        rel = arc.T_world_needle_entry[:3, :3].T @ T[:3, :3]
        phis.append(-np.arctan2(rel[1, 0], rel[0, 0]))
    phis = np.array(phis)
    assert phis[0] == pytest.approx(0.0, abs=1e-12)
    assert phis[-1] == pytest.approx(arc.insert_end_angle)
    w = np.diff(phis) / np.diff(ins.times)
    assert np.all(w >= -1e-12) and w.max() <= 0.4 * 1.001
    assert np.abs(np.diff(w) / 0.005).max() <= 2.0 * 1.05


def test_gripper_poses_and_grasp_check():
    arc = plan_needle_arc(*PhantomModel().pair(1))
    needle = NeedleModel()
    ins = arc.insertion()
    # A grasp near the base end (arc angle 160°): the jaws stay out of the tissue.
    grasp_pt = needle.point_at(np.deg2rad(160.0))
    T_gn = invert(make_transform(rpy_to_matrix((0.3, 0.2, 1.0)), grasp_pt))
    arc.check_grasp(T_gn)
    grip = gripper_poses(ins, T_gn)
    for Tg, Tn in zip(grip.poses, ins.poses, strict=True):
        np.testing.assert_allclose(Tg @ T_gn, Tn, atol=1e-12)
    base = pose_to_transform((0.1, 0.1346, 0.135), (0.6981, -0.5236, -np.pi))
    np.testing.assert_allclose(base @ in_base(grip, base).poses[3], grip.poses[3], atol=1e-12)
    # A grasp 60° behind the tip would be dragged into the tissue.
    near_tip = invert(make_transform(np.eye(3), needle.point_at(needle.tip_angle + np.deg2rad(60))))
    with pytest.raises(NeedleArcError, match="grasp point"):
        arc.check_grasp(near_tip)


def test_approach_poses_come_down_the_entry_normal_to_the_tip_before_the_entry():
    arc = plan_needle_arc(*MOVED.pair(2))
    lifted, pre = arc.approach_poses(pre_arc=0.006, lift=0.01)
    np.testing.assert_allclose(pre, arc.needle_pose(arc.pre_insertion_angle(0.006)), atol=1e-15)
    np.testing.assert_allclose(lifted[:3, 3] - pre[:3, 3], 0.01 * arc.entry.normal, atol=1e-15)
    tip = (pre @ np.r_[NeedleModel().tip, 1.0])[:3]
    assert in_port(arc.entry, tip)[2] > 0  # still outside the tissue
    assert np.linalg.norm(tip - arc.entry.position) == pytest.approx(
        2 * 0.01018 * np.sin(0.006 / 0.01018 / 2)
    )
    with pytest.raises(ValueError):
        arc.pre_insertion_angle(-1.0)


@pytest.mark.parametrize("shift", [(0.0, 0.0, -0.02), (0.0, -0.03, -0.02), (0.004, 0.011, 0.007)])
@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_the_plan_moves_with_the_phantom(pair, shift):
    # The two circles of a symmetric pair sweep the same angle up to float noise; which one is
    # planned must not depend on where the phantom stands (it once flipped at z -20 mm).
    here = plan_needle_arc(*PhantomModel().pair(pair))
    moved = plan_needle_arc(*PhantomModel(pose_to_transform(shift, (0.0, 0.0, 0.0))).pair(pair))
    expected = here.T_world_needle_entry.copy()
    expected[:3, 3] += shift
    np.testing.assert_allclose(moved.T_world_needle_entry, expected, atol=1e-9)
    assert moved.overshoot_angle == pytest.approx(here.overshoot_angle, abs=1e-9)
