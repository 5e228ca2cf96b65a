"""Waiting building blocks for skill programs: Cartesian moves, planned sweeps, the jaw, settling.

Each is a generator to ``yield from`` inside :meth:`Skill.program`: it starts the motion through
the arm's PI servo (which advances it at its own rate in simulated time), yields once per tick
until it ends, and raises :class:`SkillFailure` with the planner's reason when a move cannot be
started or fails on the way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.kinematics import JOINT_LIMITS, UnreachablePoseError, inverse_kinematics
from suture_bt.planning import CartesianMove, JointMove, PoseSequenceMove, TimedPoses, to_base
from suture_bt.planning.needle_arc import in_base
from suture_bt.planning.trajectory import JOINT_ACC, JOINT_VEL
from suture_bt.skills.base import SkillFailure, Waiting
from suture_bt.skills.context import ArmHandle


@dataclass(frozen=True)
class Speed:
    """Cartesian limits of a move: m/s, m/s², rad/s, rad/s²."""

    v_lin: float
    a_lin: float
    v_ang: float
    a_ang: float


#: Moves in free space (presenting, approaching a hover pose): 0.25 m/s, 3 rad/s (were 0.15 m/s,
#: 2 rad/s; with the faster sweeps and the settle below, runs take ~55-60 s instead of ~70 s;
#: lateral errors at the ports rose from ~0.14 to ~0.2 mm mean, a tenth of the 2.5 mm rule).
TRANSIT = Speed(0.25, 2.0, 3.0, 15.0)
#: Joint-space moves in free space (``move_to`` when a straight path would leave the joint
#: limits, e.g. the tool roll wraps): the wrist joints as fast as ``TRANSIT`` turns the tip, the
#: others at the planner's defaults (a 3.7 rad roll wrap took 3.2 s at 1.5 rad/s).
FREE_JOINT_VEL = np.r_[JOINT_VEL[:3], 3.0, 3.0, 3.0]
FREE_JOINT_ACC = np.r_[JOINT_ACC[:3], 15.0, 15.0, 15.0]
#: The last centimetre to a grasp or an entry (slower, more accurate).
FINE = Speed(0.05, 0.4, 1.2, 5.0)
#: Hold still after a move before looking or closing the jaw, until the arm has stopped (its
#: measured joints moved less than ``STILL`` in one tick), at most this long (s).
SETTLE_S = 0.10
#: Per joint, the most a still arm's measured joints move in one tick (rad; m for joint 3):
#: 0.01° and 5 µm, far below what the tip's 0.1 mm accuracy needs.
STILL = np.array([1.7e-4, 1.7e-4, 5e-6, 1.7e-4, 1.7e-4, 1.7e-4])
#: A jaw has let go of the wire once open this far (rad): the blades then stand about 3.5 mm
#: apart where they held the 0.72 mm wire, and the arm can back off while it opens further
#: (waiting for the full 0.8 rad cost about 0.2 s per release, ten releases per run).
RELEASE_OPEN = 0.4
#: The jaw has stopped when its measured angle changes less than this per tick (rad).
JAW_STILL = 1e-4


def wait(clock, seconds: float) -> Waiting:
    """Yield until ``seconds`` of simulated time have passed."""
    t_end = clock.now() + seconds
    while clock.now() < t_end - 1e-9:
        yield


def move_to(
    clock, arm: ArmHandle, goals_world, what: str, speed: Speed = TRANSIT, joint_ok: bool = True
) -> Waiting:
    """Move the tip through world poses (straight lines + SLERP), then settle.

    When the straight path leaves the joint limits on the way (the tool roll wraps), and
    ``joint_ok``, the arm goes through the goals in joint space instead (free space only).
    """
    base = arm.base_frame()
    goals = [to_base(np.asarray(g, dtype=float), base) for g in goals_world]
    move = CartesianMove(
        arm.servo, goals, v_lin=speed.v_lin, a_lin=speed.a_lin, v_ang=speed.v_ang, a_ang=speed.a_ang
    )
    st = move.start(arm.servo.setpoint_jp())
    if st.failed and joint_ok:
        qs, q = [], arm.servo.setpoint_jp()
        for goal in goals:  # through every goal (e.g. a lift first), in joint space
            try:
                q = inverse_kinematics(goal, q)
            except UnreachablePoseError as e:
                raise SkillFailure(f"{what}: {arm.name} cannot: {e.reason}") from None
            qs.append(q)
        move = JointMove(arm.servo, qs, v_max=FREE_JOINT_VEL, a_max=FREE_JOINT_ACC)
    yield from _follow(clock, arm, move, what)


def feasible(arm: ArmHandle, goals_world, q_start=None) -> str:
    """'' when every goal has an IK solution in the joint limits (each from the previous,
    starting at ``q_start`` or the arm's set-point), else the reason."""
    q = arm.servo.setpoint_jp() if q_start is None else np.asarray(q_start, dtype=float)
    base = arm.base_frame()
    for i, g in enumerate(goals_world):
        try:
            q = inverse_kinematics(to_base(np.asarray(g, dtype=float), base), q)
        except UnreachablePoseError as e:
            return f"goal {i + 1}: {e.reason}"
    return ""


def retract(clock, arm: ArmHandle, distance: float, what: str) -> Waiting:
    """Draw the tool back ``distance`` along its shaft (the insertion joint alone, as far as its
    limit allows): a retreat that is always in reach, whatever the wrist's joints are."""
    q = arm.servo.setpoint_jp()
    q[2] = max(q[2] - distance, JOINT_LIMITS[2, 0])
    yield from _follow(clock, arm, JointMove(arm.servo, [q]), what)


def move_joints(clock, arm: ArmHandle, q_goal: np.ndarray, what: str) -> Waiting:
    """Move the arm to joint set-points ``q_goal`` (joint space), then settle."""
    yield from _follow(clock, arm, JointMove(arm.servo, [np.asarray(q_goal, dtype=float)]), what)


def follow_poses(clock, arm: ArmHandle, poses_world: TimedPoses, what: str) -> Waiting:
    """Follow planner-timed tip poses (world), e.g. a needle sweep, then settle."""
    timed = in_base(poses_world, arm.base_frame())
    move = PoseSequenceMove(arm.servo, timed.times, timed.poses)
    yield from _follow(clock, arm, move, what)


def _follow(clock, arm: ArmHandle, move, what: str) -> Waiting:
    st = move.start(arm.servo.setpoint_jp())
    if st.failed:
        raise SkillFailure(f"{what}: {arm.name} cannot: {st.reason}")
    arm.servo.follow(move)
    while not (move.status.done or move.status.failed):
        yield
    if move.status.failed:
        raise SkillFailure(f"{what}: {arm.name} stopped: {move.status.reason}")
    yield from settle(clock, arm)


def settle(clock, arm: ArmHandle) -> Waiting:
    """Yield until the arm's measured joints have stopped moving (one tick at least, at most
    ``SETTLE_S``): the tracking error left after a move is mostly friction that holds the
    joint still, and waiting a fixed time for it cost a tenth of a second per move."""
    t_end = clock.now() + SETTLE_S
    before = np.asarray(arm.arm.measured_jp(), dtype=float)
    while clock.now() < t_end - 1e-9:
        yield
        now = np.asarray(arm.arm.measured_jp(), dtype=float)
        if np.all(np.abs(now - before) < STILL):
            return
        before = now


def jaw_to(arm: ArmHandle, angle: float) -> Waiting:
    """Command the jaw and wait until it has stopped (at the goal or on a wire)."""
    arm.arm.jaw.move_jp(np.array([angle]))
    previous = None
    while True:
        yield
        now = arm.jaw_angle()
        if not arm.arm.jaw.is_busy() and previous is not None and abs(now - previous) < JAW_STILL:
            return
        previous = now


def let_go(arm: ArmHandle, open_to: float) -> Waiting:
    """Open the jaw until the wire is free (``RELEASE_OPEN``), then go on opening to
    ``open_to`` without waiting: the arm can back off meanwhile."""
    yield from jaw_to(arm, min(RELEASE_OPEN, open_to))
    arm.arm.jaw.move_jp(np.array([open_to]))


def together(*motions: Waiting) -> Waiting:
    """Run waiting motions (e.g. one per arm) side by side, a step each per tick, until all
    have ended; a failure in any of them ends all (the caller's skill holds the arms)."""
    running = list(motions)
    while running:
        for m in list(running):
            try:
                next(m)
            except StopIteration:
                running.remove(m)
        if running:
            yield
