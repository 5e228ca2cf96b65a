"""``SimulatedPSM``: the robot interface (CRTK names) over the servo model, offsets and body.

Cartesian poses are the tool tip in the arm's base (RCM) frame. Everything "measured" is
what the encoders report: ``measured_jp = q_actual − Δq`` and ``measured_cp = FK(measured_jp)``,
so a hidden offset shows nowhere here. ``servo_*`` set the low-level set-point at once;
``move_*`` start a minimum-jerk joint trajectory (like the dVRK's own trajectory generator,
including ``move_cp``, which goes to the IK solution in joint space) that advances as the
world steps simulated time. Nothing blocks.
"""

from __future__ import annotations

import numpy as np

from suture_bt.interfaces import JointState
from suture_bt.kinematics import (
    JAW_LIMITS,
    JOINT_LIMITS,
    forward_kinematics,
    inverse_kinematics,
    limit_violations,
)
from suture_bt.sim.joint_offsets import JointOffset
from suture_bt.sim.joint_servo import JointServo
from suture_bt.sim.psm_body import PSMBody
from suture_bt.validation import as_joint_vector, as_pose

#: Peak joint speeds of ``move_jp`` (rad/s; m/s for insertion) and of the jaw (rad/s).
MAX_JOINT_SPEED = np.array([0.6, 0.6, 0.05, 2.0, 2.0, 2.0])
MAX_JAW_SPEED = 2.0
#: Shortest move, s.
MIN_MOVE_DURATION = 0.05
#: Jaw angle of ``jaw.open()`` (dVRK default-like 60°).
JAW_OPEN_DEFAULT = np.deg2rad(60.0)


class JointLimitError(ValueError):
    """A joint command outside the joint limits; the message names the joint(s)."""


class MinJerkTrajectory:
    """Minimum-jerk interpolation from q0 to q1 over ``duration`` starting at ``t0``."""

    def __init__(self, q0, q1, t0: float, duration: float):
        self.q0 = np.array(q0, dtype=float)
        self.q1 = np.array(q1, dtype=float)
        self.t0 = float(t0)
        self.duration = float(duration)

    @classmethod
    def with_speed_limit(cls, q0, q1, t0: float, max_speed) -> MinJerkTrajectory:
        """Shortest minimum-jerk move whose peak speed (1.875·Δ/T) stays within max_speed."""
        delta = np.abs(np.asarray(q1, dtype=float) - np.asarray(q0, dtype=float))
        duration = max(MIN_MOVE_DURATION, float(np.max(1.875 * delta / max_speed)))
        return cls(q0, q1, t0, duration)

    def sample(self, t: float) -> np.ndarray:
        s = min(1.0, max(0.0, (t - self.t0) / self.duration))
        blend = 10 * s**3 - 15 * s**4 + 6 * s**5
        return self.q0 + (self.q1 - self.q0) * blend

    def done(self, t: float) -> bool:
        return t >= self.t0 + self.duration


def _check_joint_limits(q: np.ndarray, arm: str) -> None:
    bad = limit_violations(q)
    if bad:
        raise JointLimitError(f"{arm}: command outside the joint limits: {'; '.join(bad)}")


class SimulatedJaw:
    """The jaw: set-point moved at limited speed; measured follows it, blocked by a held needle."""

    def __init__(self, arm: str, angle: float = 0.0):
        self.arm = arm
        self._setpoint = float(angle)
        self._target = float(angle)
        self._angle = float(angle)
        #: Smallest angle the jaw can reach now (set by the world while a needle is held).
        self.min_angle = 0.0

    def _checked(self, jp) -> float:
        a = float(np.asarray(jp, dtype=float).reshape(-1)[0])
        lo, hi = JAW_LIMITS
        if not (lo - 1e-9 <= a <= hi + 1e-9) or not np.isfinite(a):
            raise JointLimitError(f"{self.arm}: jaw angle {a:.4f} rad outside [{lo}, {hi}]")
        return a

    def open(self, angle: float = JAW_OPEN_DEFAULT) -> None:
        self.move_jp(angle)

    def close(self) -> None:
        self.move_jp(0.0)

    def measured_jp(self) -> np.ndarray:
        return np.array([self._angle])

    def setpoint_jp(self) -> np.ndarray:
        return np.array([self._setpoint])

    def move_jp(self, jp) -> None:
        self._target = self._checked(jp)

    def servo_jp(self, jp) -> None:
        self._target = self._setpoint = self._checked(jp)

    def is_busy(self) -> bool:
        return self._setpoint != self._target

    @property
    def goal(self) -> float:
        """Where the jaw was last commanded to go (rad)."""
        return self._target

    def update(self, dt: float) -> None:
        """Advance the jaw by one physics step."""
        step = MAX_JAW_SPEED * dt
        self._setpoint += min(step, max(-step, self._target - self._setpoint))
        goal = max(self._setpoint, self.min_angle)
        self._angle += min(step, max(-step, goal - self._angle))


class SimulatedPSM:
    """One simulated PSM implementing :class:`suture_bt.interfaces.PSMInterface`."""

    def __init__(
        self,
        name: str,
        body: PSMBody,
        servo: JointServo,
        offset: JointOffset,
        clock,
        jaw_angle: float = 0.0,
    ):
        self.name = name
        self.body = body
        self._servo = servo
        self._offset = offset
        self._clock = clock
        self._setpoint = offset.measured(servo.q)
        self._trajectory: MinJerkTrajectory | None = None
        self.jaw = SimulatedJaw(name, jaw_angle)
        self.body.set_joints(servo.q, self.jaw._angle)

    # ---------------------------------------------------------------- joint space
    def measured_js(self) -> JointState:
        return JointState(self.measured_jp(), self.measured_jv(), self._servo.effort.copy())

    def measured_jp(self) -> np.ndarray:
        return self._offset.measured(self._servo.q)

    def measured_jv(self) -> np.ndarray:
        return self._servo.qd.copy()

    def setpoint_jp(self) -> np.ndarray:
        return self._setpoint.copy()

    def servo_jp(self, jp) -> None:
        """Set the low-level set-point now (cancels any move)."""
        q = as_joint_vector(jp, self.name)
        _check_joint_limits(q, self.name)
        self._trajectory = None
        self._set_low_level(q)

    def move_jp(self, jp) -> None:
        """Start a minimum-jerk move from the current set-point to jp."""
        q = as_joint_vector(jp, self.name)
        _check_joint_limits(q, self.name)
        self._trajectory = MinJerkTrajectory.with_speed_limit(
            self._setpoint, q, self._clock.now(), MAX_JOINT_SPEED
        )

    # ---------------------------------------------------------------- Cartesian space
    def measured_cp(self) -> np.ndarray:
        return forward_kinematics(self.measured_jp())

    def setpoint_cp(self) -> np.ndarray:
        return forward_kinematics(self._setpoint)

    def ik(self, cp) -> np.ndarray:
        """Joint vector for tip pose cp (base frame), wrist branch nearest the set-point."""
        return inverse_kinematics(as_pose(cp, self.name), self._setpoint)

    def servo_cp(self, cp) -> None:
        """Set-point at the IK of cp; raises ``UnreachablePoseError`` when unreachable."""
        self.servo_jp(self.ik(cp))

    def move_cp(self, cp) -> None:
        """Joint-space minimum-jerk move to the IK of cp."""
        self.move_jp(self.ik(cp))

    def is_busy(self) -> bool:
        return self._trajectory is not None or self.jaw.is_busy()

    def base_frame(self) -> np.ndarray:
        return self.body.T_world_base.copy()

    # ---------------------------------------------------------------- simulation side
    @property
    def planned_trajectory(self) -> MinJerkTrajectory | None:
        """The move in progress (observable), or None."""
        return self._trajectory

    def _set_low_level(self, q: np.ndarray) -> None:
        self._setpoint = q.copy()
        self._servo.setpoint = self._offset.actuated(q)

    def update(self, t: float, dt: float) -> None:
        """One physics step at simulated time t (after the step): trajectory, servo, jaw."""
        if self._trajectory is not None:
            self._set_low_level(self._trajectory.sample(t))
            if self._trajectory.done(t):
                self._trajectory = None
        self._servo.step(dt)
        self.jaw.update(dt)

    def sync_body(self) -> None:
        """Reset the pybullet links to the true joint state (kinematic arm)."""
        self.body.set_joints(self._servo.q, self.jaw._angle)

    def _true_jp(self) -> np.ndarray:
        """True joint positions: private, read only by ``ground_truth`` and the world."""
        return self._servo.q.copy()

    def _true_offset(self) -> np.ndarray:
        """True Δq: private, read only by ``ground_truth``."""
        return self._offset.delta_q

    def _set_true_offset(self, delta_q) -> None:
        """Change the hidden Δq (joint-offset drift, :mod:`suture_bt.sim.faults`).

        The encoders keep reading q − Δq and the set-point keeps its measured value, so the
        joints move by the change while the readings stay where they were: a drift shows only
        in images, like the offset itself.
        """
        self._offset = JointOffset(delta_q)
        self._servo.setpoint = self._offset.actuated(self._setpoint)

    def _true_speed(self) -> float:
        """Largest true joint speed (rad/s or m/s): is the arm moving (faults: mid-move)."""
        return float(np.max(np.abs(self._servo.qd)))


__all__ = ["JOINT_LIMITS", "JointLimitError", "MinJerkTrajectory", "SimulatedJaw", "SimulatedPSM"]
