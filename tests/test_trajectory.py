"""Stepwise joint, Cartesian and pose-sequence moves: timing limits, paths and infeasibility."""

import numpy as np
import pytest

from suture_bt.kinematics import forward_kinematics
from suture_bt.planning.trajectory import (
    JOINT_ACC,
    JOINT_VEL,
    CartesianMove,
    JointMove,
    PoseSequenceMove,
    to_base,
)
from suture_bt.transforms import invert, make_transform, rotation_angle, rpy_to_matrix

Q0 = np.array([0.1, -0.2, 0.12, 0.3, 0.2, -0.1])
DT = 0.005


class RecordingSink:
    """Records every setpoint; reports the last one as its setpoint."""

    def __init__(self, q0=Q0):
        self.q = np.array(q0, dtype=float)
        self.log = []

    def servo_jp(self, q):
        self.q = np.array(q, dtype=float)
        self.log.append(self.q)

    def setpoint_jp(self):
        return self.q.copy()


def run(move, dt=DT, limit=100_000):
    statuses = []
    for _ in range(limit):
        st = move.step(dt)
        statuses.append(st)
        if st.done or st.failed:
            return statuses
    raise AssertionError("move did not finish")


def test_joint_move_respects_velocity_and_acceleration_limits():
    sink = RecordingSink()
    goal = np.array([-0.5, 0.4, 0.18, -1.0, -0.3, 0.5])
    move = JointMove(sink, goal)
    assert not move.start().failed
    sts = run(move)
    assert sts[-1].done and sts[-1].progress == 1.0
    assert all(b.progress >= a.progress for a, b in zip(sts, sts[1:], strict=False))
    q = np.array([Q0, *sink.log])
    np.testing.assert_allclose(q[-1], goal, atol=1e-12)
    vel = np.diff(q, axis=0) / DT
    acc = np.diff(vel, axis=0) / DT
    assert np.all(np.abs(vel) <= JOINT_VEL * 1.001)
    assert np.all(np.abs(acc) <= JOINT_ACC * 1.02)
    # A limit is actually reached (the move is time-optimal for its profile).
    assert np.max(np.abs(vel) / JOINT_VEL) > 0.98
    # A second step after done changes nothing.
    n = len(sink.log)
    assert move.step(DT).done and len(sink.log) == n


def test_joint_move_with_min_jerk_and_waypoints_stops_at_each():
    sink = RecordingSink()
    wps = [Q0 + 0.1, Q0 - 0.05]
    wps[0][2] = wps[1][2] = 0.1
    move = JointMove(sink, wps, profile="min_jerk")
    move.start()
    run(move)
    q = np.array(sink.log)
    assert any(np.allclose(x, wps[0], atol=1e-9) for x in q)
    np.testing.assert_allclose(q[-1], wps[1], atol=1e-12)
    assert np.all(np.abs(np.diff(q, axis=0)) / DT <= JOINT_VEL * 1.001)


def test_infeasible_joint_move_names_waypoint_and_joint():
    sink = RecordingSink()
    bad = Q0.copy()
    bad[4] = np.deg2rad(95)
    move = JointMove(sink, [Q0, bad])
    st = move.start()
    assert st.failed and not st.done
    assert "waypoint 2 of 2" in st.reason and "joint 5" in st.reason
    assert move.step(DT).failed and sink.log == []


def test_step_before_start_and_bad_input_raise():
    move = JointMove(RecordingSink(), Q0)
    with pytest.raises(RuntimeError):
        move.step(DT)
    with pytest.raises(ValueError):
        JointMove(RecordingSink(), [1.0, 2.0])
    with pytest.raises(ValueError):
        CartesianMove(RecordingSink(), np.eye(3))


def test_cartesian_move_is_straight_line_and_slerp():
    sink = RecordingSink()
    T0 = forward_kinematics(Q0)
    T1 = make_transform(
        T0[:3, :3] @ rpy_to_matrix((0.3, -0.2, 0.4)), T0[:3, 3] + [0.01, -0.02, 0.015]
    )
    move = CartesianMove(sink, T1, v_lin=0.02, a_lin=0.1, v_ang=0.5, a_ang=2.0)
    assert not move.start(Q0).failed
    run(move)
    tips = np.array([forward_kinematics(q) for q in sink.log])
    d = T1[:3, 3] - T0[:3, 3]
    rel = tips[:, :3, 3] - T0[:3, 3]
    lateral = rel - np.outer(rel @ d / (d @ d), d)
    assert np.abs(lateral).max() < 1e-9
    np.testing.assert_allclose(tips[-1], T1, atol=1e-9)
    speeds = np.linalg.norm(np.diff(tips[:, :3, 3], axis=0), axis=1) / DT
    assert speeds.max() <= 0.02 * 1.001
    # Orientation moves monotonically along the geodesic.
    ang = [rotation_angle(T0[:3, :3], T[:3, :3]) for T in tips]
    assert np.all(np.diff(ang) >= -1e-9)
    assert ang[-1] == pytest.approx(rotation_angle(T0[:3, :3], T1[:3, :3]), abs=1e-9)


def test_unreachable_cartesian_goal_fails_before_moving():
    sink = RecordingSink()
    T0 = forward_kinematics(Q0)
    far = T0.copy()
    far[:3, 3] *= 3.0  # beyond the insertion limit
    move = CartesianMove(sink, [T0, far])
    st = move.start(Q0)
    assert st.failed and "waypoint 2 of 2" in st.reason and "joint 3" in st.reason
    assert sink.log == []


def test_cartesian_path_through_a_limit_fails_with_path_position():
    # Both ends sit on the outer-pitch cone q2 = 1.0 rad; the straight chord between them
    # cuts inside the cone, where |q2| exceeds its 60° limit.
    q_a = np.array([-1.2, 1.0, 0.15, 0.0, 0.0, 0.0])
    q_b = np.array([1.2, 1.0, 0.15, 0.0, 0.0, 0.0])
    sink = RecordingSink(q_a)
    move = CartesianMove(sink, forward_kinematics(q_b))
    st = move.start()
    assert st.failed and "path to waypoint 1 of 1 at" in st.reason and "joint 2" in st.reason
    assert sink.log == []
    # Through waypoints 0.2 rad apart along the cone the chords stay inside the limit.
    goals = [forward_kinematics([q1, 1.0, 0.15, 0, 0, 0]) for q1 in np.linspace(-1.0, 1.2, 12)]
    assert not CartesianMove(sink, goals).start(q_a).failed


def test_pose_sequence_follows_timed_poses_and_to_base_round_trips():
    sink = RecordingSink()
    T0 = forward_kinematics(Q0)
    poses = [
        T0 @ make_transform(rpy_to_matrix((0, 0, 0.1 * k)), [0.001 * k, 0, 0]) for k in range(5)
    ]
    move = PoseSequenceMove(sink, [0.0, 0.1, 0.2, 0.3, 0.4], poses)
    assert not move.start(Q0).failed
    sts = run(move, dt=0.05)
    assert len(sts) == 8 and sts[-1].done
    np.testing.assert_allclose(forward_kinematics(sink.log[1]), poses[1], atol=1e-9)
    np.testing.assert_allclose(forward_kinematics(sink.log[-1]), poses[-1], atol=1e-9)
    base = make_transform(rpy_to_matrix((0.3, -0.5, 2.0)), [0.1, 0.2, 0.3])
    np.testing.assert_allclose(to_base(base @ T0, base), T0, atol=1e-12)
    np.testing.assert_allclose(invert(base) @ base, np.eye(4), atol=1e-12)
    with pytest.raises(ValueError, match="increase"):
        PoseSequenceMove(sink, [0.0, 0.0], poses[:2])


def test_numpy_slerp_matches_scipy_including_near_opposite_quaternions():
    from scipy.spatial.transform import Rotation, Slerp

    from suture_bt.planning.trajectory import _slerp_matrix

    rng = np.random.default_rng(5)
    pairs = [Rotation.random(2, random_state=int(rng.integers(1 << 30))) for _ in range(100)]
    pairs.append(Rotation.from_rotvec([[0, 0, 0], [0, 0, np.pi - 1e-6]]))
    for r in pairs:
        s = float(rng.uniform())
        ref = Slerp([0.0, 1.0], r)([s]).as_matrix()[0]
        qa, qb = r.as_quat()
        np.testing.assert_allclose(_slerp_matrix(qa, -qb, s), ref, atol=1e-8)
