"""Stepwise joint and Cartesian moves that feed setpoints to a servo (the PI loop or an arm).

A move is built, then ``start(q_start)`` checks every waypoint for IK feasibility and joint
limits and plans the timing; ``step(dt)`` advances it by ``dt`` seconds of simulated time, sends
one joint setpoint through ``sink.servo_jp`` and returns a :class:`MoveStatus`. Nothing blocks,
so a behaviour-tree tick can drive it. An infeasible move does not raise: ``start`` returns a
failed status whose reason names the waypoint and the joint. Poses are tip poses in the arm's
base (RCM) frame, as ``measured_cp`` reports them; :func:`to_base` converts world poses.
With a :class:`~suture_bt.control.PIServo` as sink, hand the started move to
``servo.follow(move)``: the servo then steps it at its own rate and the caller polls
``move.status``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from suture_bt.kinematics import (
    NUM_JOINTS,
    UnreachablePoseError,
    forward_kinematics,
    inverse_kinematics,
    limit_violations,
)
from suture_bt.planning.timing import Profile, make_profile
from suture_bt.transforms import invert
from suture_bt.validation import as_joint_vector, as_pose

#: Default joint limits for moves: revolute rad/s, rad/s²; prismatic m/s, m/s².
JOINT_VEL = np.array([0.6, 0.6, 0.05, 1.5, 1.5, 1.5])
JOINT_ACC = np.array([2.0, 2.0, 0.2, 5.0, 5.0, 5.0])
#: Default Cartesian limits: linear m/s, m/s²; angular rad/s, rad/s².
LIN_VEL, LIN_ACC, ANG_VEL, ANG_ACC = 0.02, 0.1, 0.6, 2.0
#: Cartesian paths are IK-checked at samples this close (m, rad).
CHECK_STEP_LIN, CHECK_STEP_ANG = 0.0005, np.deg2rad(1.0)
#: A joint change larger than this between neighbouring path samples means an IK branch jump.
MAX_JOINT_JUMP = np.array([0.1, 0.1, 0.005, 0.35, 0.35, 0.35])


class SetpointSink(Protocol):
    """Anything that accepts joint setpoints: a PIServo or a PSMInterface."""

    def servo_jp(self, jp) -> None: ...


@dataclass(frozen=True)
class MoveStatus:
    """Progress in [0, 1]; done and failed are exclusive; reason explains a failure."""

    progress: float
    done: bool = False
    failed: bool = False
    reason: str = ""


def to_base(T_world: np.ndarray, T_world_base: np.ndarray) -> np.ndarray:
    """A world pose expressed in an arm's base frame (``T_world_base = psm.base_frame()``)."""
    return invert(T_world_base) @ np.asarray(T_world, dtype=float)


def _jump_reason(q_prev: np.ndarray, q: np.ndarray) -> str:
    jump = np.abs(q - q_prev) > MAX_JOINT_JUMP
    if not np.any(jump):
        return ""
    j = int(np.argmax(jump))
    return (
        f"joint {j + 1} jumps {q[j] - q_prev[j]:+.3f} between path samples "
        "(IK branch switch or singularity)"
    )


class _Move:
    """Shared state machine: idle → running → done | failed."""

    def __init__(self, sink: SetpointSink):
        self.sink = sink
        self.elapsed = 0.0
        self.duration = 0.0
        self.setpoint: np.ndarray | None = None
        self.status = MoveStatus(0.0)
        self.started = False

    def _start_q(self, q_start) -> np.ndarray:
        if q_start is None:
            if not hasattr(self.sink, "setpoint_jp"):
                raise ValueError("q_start is required when the sink has no setpoint_jp()")
            q_start = self.sink.setpoint_jp()
        return as_joint_vector(q_start, "q_start")

    def _fail(self, reason: str) -> MoveStatus:
        self.status = MoveStatus(self.status.progress, failed=True, reason=reason)
        return self.status

    def _setpoint_at(self, t: float) -> np.ndarray:
        raise NotImplementedError

    def step(self, dt: float) -> MoveStatus:
        """Advance by ``dt`` seconds, send the setpoint, return the status."""
        if not self.started:
            raise RuntimeError("call start() before step()")
        if self.status.done or self.status.failed:
            return self.status
        if not np.isfinite(dt) or dt < 0:
            raise ValueError(f"dt must be finite and non-negative, got {dt}")
        self.elapsed = min(self.elapsed + dt, self.duration)
        if self.duration - self.elapsed < 1e-9:  # absorb float round-off of summed steps
            self.elapsed = self.duration
        try:
            q = self._setpoint_at(self.elapsed)
        except UnreachablePoseError as exc:
            return self._fail(f"at t={self.elapsed:.3f} s: {exc.reason}")
        self.setpoint = q
        self.sink.servo_jp(q)
        done = self.elapsed >= self.duration
        progress = 1.0 if self.duration <= 0 else self.elapsed / self.duration
        self.status = MoveStatus(progress, done=done)
        return self.status


class JointMove(_Move):
    """Joint-space move through waypoints, stopping at each, under per-joint vel/acc limits."""

    def __init__(
        self,
        sink: SetpointSink,
        waypoints,
        v_max=JOINT_VEL,
        a_max=JOINT_ACC,
        profile: str = "trapezoidal",
    ):
        super().__init__(sink)
        wps = np.asarray(waypoints, dtype=float)
        if wps.ndim == 1:
            wps = wps[None]
        self.waypoints = [as_joint_vector(w, f"waypoint {i}") for i, w in enumerate(wps)]
        if not self.waypoints:
            raise ValueError("a joint move needs at least one waypoint")
        self.v_max = np.broadcast_to(np.asarray(v_max, dtype=float), (NUM_JOINTS,))
        self.a_max = np.broadcast_to(np.asarray(a_max, dtype=float), (NUM_JOINTS,))
        self.profile_kind = profile
        self.segments: list[tuple[np.ndarray, np.ndarray, Profile, float]] = []

    def start(self, q_start=None) -> MoveStatus:
        """Check every waypoint against the joint limits and plan the timing."""
        q0 = self._start_q(q_start)
        self.started, self.elapsed, self.segments = True, 0.0, []
        n = len(self.waypoints)
        for i, w in enumerate(self.waypoints):
            bad = limit_violations(w)
            if bad:
                return self._fail(f"waypoint {i + 1} of {n}: " + "; ".join(bad))
        t, prev = 0.0, q0
        for w in self.waypoints:
            prof = make_profile(self.profile_kind, w - prev, self.v_max, self.a_max)
            self.segments.append((prev, w, prof, t))
            t += prof.duration
            prev = w
        self.duration = t
        self.status = MoveStatus(0.0)
        return self.status

    def _setpoint_at(self, t: float) -> np.ndarray:
        for q_a, q_b, prof, t0 in self.segments:
            if t <= t0 + prof.duration:
                return q_a + prof.s(t - t0) * (q_b - q_a)
        return self.segments[-1][1].copy()


def _pose_distance(Ta: np.ndarray, Tb: np.ndarray) -> tuple[float, float]:
    lin = float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3]))
    ang = float(Rotation.from_matrix(Ta[:3, :3].T @ Tb[:3, :3]).magnitude())
    return lin, ang


def _quat(R: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(R).as_quat()  # (x, y, z, w), robust near 180°


def _slerp_matrix(qa: np.ndarray, qb: np.ndarray, s: float) -> np.ndarray:
    """Rotation matrix at fraction s of the shortest arc from quaternion qa to qb (numpy)."""
    d = float(np.dot(qa, qb))
    if d < 0.0:
        qb, d = -qb, -d
    if d > 0.9995:
        q = qa + s * (qb - qa)
    else:
        th = np.arccos(min(d, 1.0))
        q = (np.sin((1 - s) * th) * qa + np.sin(s * th) * qb) / np.sin(th)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _interpolate(Ta: np.ndarray, Tb: np.ndarray, qa: np.ndarray, qb: np.ndarray, s: float):
    """Pose at fraction s: straight-line position, SLERP orientation."""
    s = min(max(s, 0.0), 1.0)
    T = np.eye(4)
    T[:3, :3] = _slerp_matrix(qa, qb, s)
    T[:3, 3] = (1 - s) * Ta[:3, 3] + s * Tb[:3, 3]
    return T


@dataclass
class _CartSegment:
    T_a: np.ndarray
    T_b: np.ndarray
    profile: Profile
    t0: float

    def __post_init__(self):
        self.q_a, self.q_b = _quat(self.T_a[:3, :3]), _quat(self.T_b[:3, :3])

    def pose(self, s: float) -> np.ndarray:
        return _interpolate(self.T_a, self.T_b, self.q_a, self.q_b, s)


class CartesianMove(_Move):
    """Straight-line position + SLERP orientation through goal poses, via the closed-form IK.

    ``start`` IK-checks each goal and the path between goals at samples ≤ 0.5 mm / 1° apart
    (including IK branch jumps); ``step`` solves the IK at the interpolated pose, choosing the
    branch nearest the previous setpoint.
    """

    def __init__(
        self,
        sink: SetpointSink,
        goals,
        v_lin: float = LIN_VEL,
        a_lin: float = LIN_ACC,
        v_ang: float = ANG_VEL,
        a_ang: float = ANG_ACC,
        profile: str = "trapezoidal",
    ):
        super().__init__(sink)
        g = np.asarray(goals, dtype=float)
        if g.ndim == 2:
            g = g[None]
        self.goals = [as_pose(T, f"goal {i + 1}") for i, T in enumerate(g)]
        if not self.goals:
            raise ValueError("a Cartesian move needs at least one goal pose")
        self.limits = (v_lin, a_lin, v_ang, a_ang)
        self.profile_kind = profile
        self.segments: list[_CartSegment] = []
        self.checked_path: list[np.ndarray] = []
        self._q_prev: np.ndarray | None = None

    def start(self, q_start=None) -> MoveStatus:
        """IK-check every goal and the path, and plan the timing; fails with the reason."""
        q0 = self._start_q(q_start)
        self.started, self.elapsed, self.segments, self.checked_path = True, 0.0, [], [q0]
        self._q_prev = q0
        v_lin, a_lin, v_ang, a_ang = self.limits
        n = len(self.goals)
        T_prev, q_prev, t = forward_kinematics(q0), q0, 0.0
        for i, T_goal in enumerate(self.goals):
            where = f"waypoint {i + 1} of {n}"
            try:
                inverse_kinematics(T_goal, q_prev)
            except UnreachablePoseError as exc:
                return self._fail(f"{where}: {exc.reason}")
            lin, ang = _pose_distance(T_prev, T_goal)
            seg = _CartSegment(
                T_prev,
                T_goal,
                make_profile(self.profile_kind, [lin, ang], [v_lin, v_ang], [a_lin, a_ang]),
                t,
            )
            k = max(1, int(np.ceil(max(lin / CHECK_STEP_LIN, ang / CHECK_STEP_ANG))))
            for s in np.linspace(0.0, 1.0, k + 1)[1:]:
                try:
                    q = inverse_kinematics(seg.pose(s), q_prev)
                except UnreachablePoseError as exc:
                    return self._fail(f"path to {where} at {100 * s:.0f}%: {exc.reason}")
                jump = _jump_reason(q_prev, q)
                if jump:
                    return self._fail(f"path to {where} at {100 * s:.0f}%: {jump}")
                self.checked_path.append(q)
                q_prev = q
            self.segments.append(seg)
            t += seg.profile.duration
            T_prev = T_goal
        self.duration = t
        self.status = MoveStatus(0.0)
        return self.status

    def pose_at(self, t: float) -> np.ndarray:
        """Planned tip pose (base frame) at time t of the move."""
        for seg in self.segments:
            if t <= seg.t0 + seg.profile.duration:
                return seg.pose(seg.profile.s(t - seg.t0))
        return self.segments[-1].T_b.copy()

    def _setpoint_at(self, t: float) -> np.ndarray:
        q = inverse_kinematics(self.pose_at(t), self._q_prev)
        self._q_prev = q
        return q


class PoseSequenceMove(_Move):
    """Follow timed tip poses (base frame), interpolating linearly + SLERP between them.

    For planned paths such as the needle arc, whose timing is already set by the planner.
    """

    def __init__(self, sink: SetpointSink, times: Sequence[float], poses):
        super().__init__(sink)
        self.times = np.asarray(times, dtype=float).reshape(-1)
        P = np.asarray(poses, dtype=float)
        if P.ndim != 3 or P.shape[0] != self.times.shape[0] or self.times.shape[0] < 2:
            raise ValueError("need at least two poses and one time per pose")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError("pose times must increase strictly")
        self.poses = [as_pose(T, f"pose {i + 1}") for i, T in enumerate(P)]
        self.joint_path: list[np.ndarray] = []
        self._quats = [_quat(T[:3, :3]) for T in self.poses]
        self._q_prev: np.ndarray | None = None

    def start(self, q_start=None) -> MoveStatus:
        """IK-check every pose, in order, each from the previous solution."""
        q_prev = self._start_q(q_start)
        self.started, self.elapsed, self.joint_path = True, 0.0, []
        n = len(self.poses)
        for i, T in enumerate(self.poses):
            try:
                q = inverse_kinematics(T, q_prev)
            except UnreachablePoseError as exc:
                return self._fail(f"waypoint {i + 1} of {n}: {exc.reason}")
            jump = _jump_reason(q_prev, q) if i > 0 else ""
            if jump:
                return self._fail(f"waypoint {i + 1} of {n}: {jump}")
            self.joint_path.append(q)
            q_prev = q
        self._q_prev = self.joint_path[0]
        self.duration = float(self.times[-1] - self.times[0])
        self.status = MoveStatus(0.0)
        return self.status

    def pose_at(self, t: float) -> np.ndarray:
        """Interpolated tip pose at time t of the move (t = 0 is the first pose)."""
        tt = self.times[0] + min(max(t, 0.0), self.duration)
        i = int(np.clip(np.searchsorted(self.times, tt, side="right") - 1, 0, len(self.poses) - 2))
        s = (tt - self.times[i]) / (self.times[i + 1] - self.times[i])
        a, b = self.poses[i], self.poses[i + 1]
        return _interpolate(a, b, self._quats[i], self._quats[i + 1], s)

    def _setpoint_at(self, t: float) -> np.ndarray:
        q = inverse_kinematics(self.pose_at(t), self._q_prev)
        self._q_prev = q
        return q
