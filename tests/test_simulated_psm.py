"""SimulatedPSM: CRTK interface, ports reachable exactly, hidden offsets, non-blocking moves."""

import numpy as np
import pytest

from suture_bt.interfaces import PSMInterface
from suture_bt.kinematics import UnreachablePoseError, forward_kinematics
from suture_bt.sim import ground_truth
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.simulated_psm import JointLimitError, MinJerkTrajectory
from suture_bt.sim.world import World
from suture_bt.transforms import invert

#: Which arm serves which ports: PSM2 (at −x) the entries, PSM1 (at +x) the exits.
ARM_FOR_KIND = {"entry": "psm2", "exit": "psm1"}


@pytest.fixture(scope="module")
def ideal_world():
    with World.from_scene(scene_from_dict({"servo": {"error_model": False}})) as w:
        yield w


def test_implements_the_robot_interface(ideal_world):
    assert isinstance(ideal_world.psm1, PSMInterface)
    assert isinstance(ideal_world.psm2, PSMInterface)


def test_servo_cp_to_every_port_lands_the_true_tip(ideal_world):
    w = ideal_world
    gt = ground_truth.GroundTruth(w)
    for port in w.task.phantom.ports():
        arm = w.arms[ARM_FOR_KIND[port.kind]]
        arm.servo_cp(invert(arm.base_frame()) @ port.tip_pose_into_tissue())
        w.step(0.005)
        tip = gt.tip_pose_world(arm.name)
        assert np.linalg.norm(tip[:3, 3] - port.position) < 0.5e-3, port.name
        assert np.allclose(tip[:3, 2], -port.normal, atol=1e-4)


def test_offset_b_is_hidden_in_measurements():
    scene = scene_from_dict(
        {"servo": {"error_model": False}, "arms": {"psm2": {"joint_offset": "B"}}}
    )
    with World.from_scene(scene) as w:
        port = w.task.phantom.port("entry2")
        goal = invert(w.psm2.base_frame()) @ port.tip_pose_into_tissue()
        w.psm2.servo_cp(goal)
        w.step(0.01)
        # The arm reports exactly the commanded pose ...
        assert np.allclose(w.psm2.measured_cp(), goal, atol=1e-9)
        assert np.allclose(w.psm2.measured_jp(), w.psm2.setpoint_jp(), atol=1e-12)
        # ... while the true tip is millimetres away.
        gt = ground_truth.GroundTruth(w)
        err = np.linalg.norm(gt.tip_pose_world("psm2")[:3, 3] - port.position)
        assert 2e-3 < err < 20e-3
        dq = gt.joint_offset("psm2")
        assert np.allclose(np.rad2deg(dq[:2]), [2.52, -0.46]) and dq[2] == pytest.approx(0.004)


def test_servo_error_shows_in_measured_joints():
    with World.from_scene(scene_from_dict({"arms": {"psm1": {"joint_offset": "zero"}}})) as w:
        q = w.psm1.setpoint_jp() + np.array([0.1, 0.1, 0.01, 0.1, 0.1, 0.1])
        w.psm1.servo_jp(q)
        w.step(1.0)
        err = q - w.psm1.measured_jp()
        assert np.all(np.abs(np.rad2deg(err[[0, 3, 4, 5]])) > 1.0)
        assert 0.03e-3 < abs(err[2]) < 0.2e-3


def test_move_jp_is_non_blocking_and_min_jerk(ideal_world):
    w = ideal_world
    q0 = np.array([0.3, -0.2, 0.12, 0.5, -0.3, 0.1])
    w.psm1.servo_jp(q0)
    goal = q0 + np.array([0.2, -0.1, 0.01, 0.3, 0.1, -0.1])
    w.psm1.move_jp(goal)
    assert w.psm1.is_busy()
    traj = w.psm1.planned_trajectory
    assert isinstance(traj, MinJerkTrajectory) and traj.duration > 0.2
    w.step(traj.duration / 2)
    mid = w.psm1.setpoint_jp()
    assert np.allclose(mid, (q0 + goal) / 2, atol=0.02)  # min-jerk is symmetric in time
    w.step(traj.duration / 2 + 0.01)
    assert not w.psm1.is_busy()
    assert np.allclose(w.psm1.measured_jp(), goal, atol=1e-12)
    assert np.allclose(w.psm1.setpoint_cp(), forward_kinematics(goal))


def test_move_cp_goes_to_the_ik_solution(ideal_world):
    w = ideal_world
    goal = invert(w.psm2.base_frame()) @ w.task.phantom.port("entry3").tip_pose_into_tissue()
    w.psm2.move_cp(goal)
    while w.psm2.is_busy():
        w.step(0.1)
    assert np.allclose(w.psm2.measured_cp(), goal, atol=1e-9)


def test_bad_commands_raise_clear_errors(ideal_world):
    arm = ideal_world.psm1
    q = arm.setpoint_jp()
    with pytest.raises(JointLimitError, match="joint 3"):
        arm.servo_jp(np.r_[q[:2], 0.5, q[3:]])
    with pytest.raises(JointLimitError, match="joint 2"):
        arm.move_jp(np.r_[q[0], 2.0, q[2:]])
    with pytest.raises(ValueError, match="6 finite joint values"):
        arm.servo_jp([0.0, 0.1])
    far = np.eye(4)
    far[:3, 3] = (0.0, 0.0, -0.5)  # beyond the insertion limit
    with pytest.raises(UnreachablePoseError) as info:
        arm.servo_cp(far)
    assert "joint 3" in info.value.reason
    with pytest.raises(JointLimitError, match="jaw"):
        arm.jaw.move_jp(2.0)


def test_jaw_moves_at_limited_speed(ideal_world):
    jaw = ideal_world.psm1.jaw
    jaw.open()
    ideal_world.step(0.1)
    assert 0.15 < jaw.measured_jp()[0] < 0.25  # 2 rad/s
    ideal_world.step(1.0)
    assert jaw.measured_jp()[0] == pytest.approx(np.deg2rad(60.0))
    jaw.close()
    ideal_world.step(1.0)
    assert jaw.measured_jp()[0] == pytest.approx(0.0)
