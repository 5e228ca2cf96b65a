"""High-level joint PI servo on top of the arm's low-level servo (seed Fig. 1a), stepwise.

The low-level joint servo of each arm leaves a steady-state error (load, friction, limited
bandwidth; DESIGN.md §5). This loop runs at a fixed simulated rate as a world periodic
callback (``world.add_periodic(1 / rate, servo.update)``), reads ``measured_jp``, and sends
``servo_jp`` = desired + correction, where the correction is a PI term on the joint error plus
a velocity feed-forward of the low-level lag; the integrator removes the steady-state error.

With an offset estimate Δq̂ (joints 1-3) the loop works on TRUE joints: it compares the desired
q_d with q̂ = q_meas + Δq̂ and sends (q_d + correction) − Δq̂; see
:mod:`suture_bt.control.offset_compensation` for the derivation from the offset model. With
Δq̂ = Δq the true joints converge to q_d.

Anti-windup is conditional integration: a joint whose output is saturated (at a joint limit or
at ``max_correction``) stops integrating while its error pushes further into saturation; the
integrator is also bounded by ``integrator_limit``. Every quantity of the last update is kept
on the object (desired, measured, estimate, error, integrator, correction, commanded).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from suture_bt.control.offset_compensation import command_for_true, full_offset, true_from_measured
from suture_bt.control.plant_estimate import PlantEstimator
from suture_bt.kinematics import JOINT_LIMITS, NUM_JOINTS


class JointServoArm(Protocol):
    """What the PI servo needs of an arm (a subset of PSMInterface)."""

    def measured_jp(self) -> np.ndarray: ...
    def servo_jp(self, jp) -> None: ...


def _per_joint(value, name: str) -> np.ndarray:
    v = np.broadcast_to(np.asarray(value, dtype=float), (NUM_JOINTS,)).copy()
    if np.any(~np.isfinite(v)) or np.any(v < 0):
        raise ValueError(f"{name} must be finite and non-negative per joint, got {v}")
    return v


#: The low-level servo's Kd/Kp = 2ζ/ω (critically damped, 6 Hz bandwidth; DESIGN.md §5 servo).
LOW_LEVEL_LAG = 2.0 / (2.0 * np.pi * 6.0)


@dataclass(frozen=True)
class PIGains:
    """Per-joint gains (kp dimensionless, ki in 1/s), output bounds and velocity feed-forward.

    Why these defaults (tuned with ``benchmarks/servo.py`` against the simulated low-level servo,
    a PD loop of about 6 Hz bandwidth with Coulomb friction and load):

    * ``ki = 60 /s``: the integrator is what removes the friction/load error; 60 /s settles it
      in about 0.1 s while ki·dt = 0.3 at 200 Hz keeps the loop stable even on an ideal arm
      that reaches its command at once (the discrete loop is stable for kp < 1 and
      ki·dt < 2(1 − kp)).
    * ``kp = 0.5``: adds push against a stuck joint without ringing; above 1 the loop with an
      ideal arm would oscillate.
    * ``velocity_feedforward = Kd/Kp`` of the low-level servo (0.053 s): a PD servo tracking a
      ramp lags by (Kd/Kp)·q̇; feeding that forward keeps the integrator from soaking up the lag,
      which it would otherwise release as an overshoot when the motion stops — and stiction then
      holds the joint on the wrong side (steady-state error 10-20× larger without it).
    * ``direction_memory``: each joint starts every motion from the integrator of its last
      motion in that direction (see :meth:`PIServo._switch_direction`), because the friction
      it cancels flips with the direction and relaxes during holds; ``direction_deadband``
      (0.002 rad/s, 0.1 mm/s) must be below the slowest joint speeds of a needle sweep. In the
      simulated throws of ``tests/test_motion_integration.py`` the tissue strain reached
      0.54 mm in an insertion without any memory and 0.66 mm in an extraction with a memory
      of reversals only (limit 0.5 mm); with this memory it stays ≤ 0.25 mm.
    * ``max_correction`` (0.15 rad, 5 mm) and ``integrator_limit`` bound how far the loop may push
      beyond the desired value: several times the expected error (1.5°, 0.1 mm), so a blocked
      arm cannot make it drive a joint far away.
    * ``adaptive`` (default): the robot is not the model. A :class:`PlantEstimator` identifies
      each joint's low-level servo online from measured and commanded joints only, and the
      loop schedules itself on the estimate ω̂: the velocity feed-forward becomes the
      estimated lag (Kd/Kp), an acceleration feed-forward 1/ω̂² is added, and for plants
      slower than ``reference_bandwidth_hz`` the integral gain falls as (ω̂/ω_ref)² while kp
      rises toward ``slow_plant_kp`` (a 60 /s integrator on a 3 Hz servo overshoots into
      stiction and hunts: 86-89 % of the error removed instead of 99 %; see
      ``benchmarks/servo.py``). Until a joint has moved enough, the estimate is the nominal
      6 Hz servo, i.e. exactly the fixed gains. ``adaptive=False`` keeps the fixed gains.
    """

    kp: np.ndarray = field(default_factory=lambda: np.full(NUM_JOINTS, 0.5))
    ki: np.ndarray = field(default_factory=lambda: np.full(NUM_JOINTS, 60.0))
    max_correction: np.ndarray = field(
        default_factory=lambda: np.array([0.15, 0.15, 0.005, 0.15, 0.15, 0.15])
    )
    integrator_limit: np.ndarray = field(
        default_factory=lambda: np.array([0.15, 0.15, 0.005, 0.15, 0.15, 0.15])
    )
    velocity_feedforward: float = LOW_LEVEL_LAG
    direction_memory: bool = True
    direction_deadband: np.ndarray = field(
        default_factory=lambda: np.array([0.002, 0.002, 0.0001, 0.002, 0.002, 0.002])
    )
    adaptive: bool = True
    reference_bandwidth_hz: float = 6.0
    slow_plant_kp: float = 0.8

    def __post_init__(self):
        if not np.isfinite(self.velocity_feedforward) or self.velocity_feedforward < 0:
            raise ValueError("velocity_feedforward must be a non-negative time constant (s)")
        for name in ("kp", "ki", "max_correction", "integrator_limit", "direction_deadband"):
            object.__setattr__(self, name, _per_joint(getattr(self, name), name))


class PIServo:
    """Joint PI loop with offset compensation for one arm; call :meth:`update` periodically."""

    def __init__(
        self,
        arm: JointServoArm,
        rate: float = 200.0,
        gains: PIGains | None = None,
        offset_estimate=(0.0, 0.0, 0.0),
        enabled: bool = True,
        joint_limits: np.ndarray = JOINT_LIMITS,
    ):
        if not np.isfinite(rate) or rate <= 0:
            raise ValueError(f"rate must be positive, got {rate}")
        self.arm = arm
        self.rate = float(rate)
        self.dt = 1.0 / self.rate
        self.gains = gains or PIGains()
        self.enabled = enabled
        self.joint_limits = np.asarray(joint_limits, dtype=float)
        self.offset_estimate = full_offset(offset_estimate)
        self.desired: np.ndarray | None = None
        self._previous_desired: np.ndarray | None = None
        self.desired_velocity = np.zeros(NUM_JOINTS)
        self.measured = np.zeros(NUM_JOINTS)
        self.estimate = np.zeros(NUM_JOINTS)
        self.error = np.zeros(NUM_JOINTS)
        self.integrator = np.zeros(NUM_JOINTS)
        #: Online estimate of the low-level servo (None with fixed gains).
        self.estimator = PlantEstimator(self.dt) if self.gains.adaptive else None
        self.desired_acceleration = np.zeros(NUM_JOINTS)
        #: Gains used by the last update, per joint (scheduled on the estimate when adaptive).
        self.kp = self.gains.kp.copy()
        self.ki = self.gains.ki.copy()
        #: Direction of the desired motion per joint (+1, −1; 0 before the first motion).
        self.direction = np.zeros(NUM_JOINTS, dtype=int)
        self._memory = np.zeros((2, NUM_JOINTS))  # integrator per direction: [−, +]
        self._learned = np.zeros((2, NUM_JOINTS), dtype=bool)
        self._moving = np.zeros(NUM_JOINTS, dtype=bool)
        self.correction = np.zeros(NUM_JOINTS)
        self.output = np.zeros(NUM_JOINTS)
        self.commanded = np.zeros(NUM_JOINTS)
        self.saturated = np.zeros(NUM_JOINTS, dtype=bool)
        self.updates = 0
        self.last_time: float | None = None
        #: A move (anything with ``step(dt)`` returning a status) advanced by every update.
        self.source = None

    # -- setpoints -------------------------------------------------------------------------
    def servo_jp(self, q_desired) -> None:
        """Set the desired TRUE joints (the next update acts on it); never blocks."""
        q = np.asarray(q_desired, dtype=float).reshape(-1)
        if q.shape != (NUM_JOINTS,) or not np.all(np.isfinite(q)):
            raise ValueError(f"desired joints must be {NUM_JOINTS} finite values, got {q}")
        self.desired = q.copy()

    def setpoint_jp(self) -> np.ndarray:
        """The desired TRUE joints (the current estimate when nothing was set yet)."""
        return self.desired.copy() if self.desired is not None else self.estimated_jp()

    def estimated_jp(self) -> np.ndarray:
        """Estimate of the TRUE joints: measured + Δq̂."""
        return true_from_measured(self.arm.measured_jp(), self.offset_estimate)

    def set_offset_estimate(self, offset, hold_pose: bool = False) -> None:
        """Use a new Δq̂ (joints 1-3); the integrator is kept (it models the load, not Δq).
        ``hold_pose``: the desired joints move with the estimate, so the arm stays where it is
        (a provisional estimate installed while the arm holds something)."""
        new = full_offset(offset)
        if hold_pose and self.desired is not None:
            self.desired = self.desired + (new - self.offset_estimate)
        self.offset_estimate = new

    def reset(self, hold_current: bool = True) -> None:
        """Zero the integrator; optionally make the current estimate the desired value."""
        self.integrator[:] = 0.0
        self.direction[:] = 0
        self._memory[:] = 0.0
        self._learned[:] = False
        self._moving[:] = False
        self._previous_desired = None
        self.desired = self.estimated_jp() if hold_current else None

    def follow(self, move) -> None:
        """Advance ``move`` (a started trajectory whose sink is this servo) at the loop's rate.

        The move then produces one setpoint per update, in simulated time, however coarsely
        the caller steps the world (a behaviour-tree tick of 50 ms gives the same motion as
        5 ms steps); the caller polls ``move.status``. A new ``follow`` replaces the old move.
        """
        if getattr(move, "sink", self) is not self:
            raise ValueError("the move feeds another sink; build it with this servo as sink")
        if not getattr(move, "started", True):
            raise ValueError("start the move before handing it to the servo")
        self.source = move

    def stop_following(self) -> None:
        """Drop the followed move; the last desired value is held."""
        self.source = None

    # -- the loop --------------------------------------------------------------------------
    def update(self, t: float | None = None) -> None:
        """One loop iteration: read, compute, send (signature fits ``world.add_periodic``)."""
        self.last_time = t
        if self.source is not None:
            st = self.source.step(self.dt)
            if st.done or st.failed:
                self.source = None
        self.measured = np.asarray(self.arm.measured_jp(), dtype=float).copy()
        self.estimate = true_from_measured(self.measured, self.offset_estimate)
        if self.desired is None:
            self.desired = self.estimate.copy()
        q_d = self.desired
        prev = self._previous_desired
        v_prev = self.desired_velocity
        self.desired_velocity = np.zeros(NUM_JOINTS) if prev is None else (q_d - prev) / self.dt
        self.desired_acceleration = (self.desired_velocity - v_prev) / self.dt
        if prev is None:
            self.desired_acceleration = np.zeros(NUM_JOINTS)
        self._previous_desired = q_d.copy()
        if self.estimator is not None and self.enabled:
            self.estimator.observe(self.measured, self.commanded if self.updates else None)
        feedforward = self._schedule()
        g = self.gains
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        e = q_d - self.estimate
        self.error = e
        if self.enabled:
            if g.direction_memory:
                self._switch_direction(self.desired_velocity)
            integ = np.clip(
                self.integrator + self.ki * e * self.dt, -g.integrator_limit, g.integrator_limit
            )
            raw = self.kp * e + integ + feedforward
            corr = np.clip(raw, -g.max_correction, g.max_correction)
            out = np.clip(q_d + corr, lo, hi)
            # Conditional integration: hold a saturated joint's integrator while the error
            # pushes further into the saturation.
            excess = (q_d + raw) - out
            self.saturated = np.abs(excess) > 1e-15
            hold = self.saturated & (np.sign(e) == np.sign(excess))
            self.integrator = np.where(hold, self.integrator, integ)
            if g.direction_memory:
                self._remember_direction()
        else:
            out = np.clip(q_d, lo, hi)
            self.saturated = out != q_d
        self.correction = out - q_d
        self.output = out
        self.commanded = np.clip(command_for_true(out, self.offset_estimate), lo, hi)
        self.arm.servo_jp(self.commanded)
        self.updates += 1

    def _schedule(self) -> np.ndarray:
        """Set this update's kp, ki per joint and return the feed-forward term (see PIGains)."""
        g = self.gains
        if self.estimator is None:
            self.kp, self.ki = g.kp, g.ki
            return g.velocity_feedforward * self.desired_velocity
        w = self.estimator.bandwidth
        w_ref = 2 * np.pi * g.reference_bandwidth_hz
        slow = np.clip(w_ref / w - 1.0, 0.0, 1.0)  # 0 at or above the reference, 1 at half
        self.kp = g.kp + (np.maximum(g.slow_plant_kp, g.kp) - g.kp) * slow
        self.ki = g.ki * np.minimum(1.0, (w / w_ref) ** 2)
        return (
            self.estimator.lag * self.desired_velocity
            + self.estimator.inverse_stiffness * self.desired_acceleration
        )

    def _switch_direction(self, velocity: np.ndarray) -> None:
        """Swap in the integrator learned while moving in the new direction, per joint.

        Coulomb friction flips sign with the direction of motion, so the integral term that
        holds a joint against friction (and load) while it moves one way is wrong by twice the
        friction the other way; and after a hold it has relaxed to anywhere inside the friction
        band. Integrating that difference away whenever a joint starts or reverses is what
        makes a PI loop lag on a stiction plant. So each joint remembers the integrator of its
        last motion in each direction (speeds inside ``direction_deadband`` count as rest) and
        starts every motion from it; a direction never seen starts from the mirror image of the
        other one (a friction-dominated guess). A memory that would move the integrator against
        the new direction is stale (friction compensation for motion in direction d is load + d·f,
        f ≥ 0, so starting to move in d can only shift it toward d) and is not used.
        """
        db = self.gains.direction_deadband
        moving = np.abs(velocity) > db
        new = np.where(moving, np.sign(velocity).astype(int), self.direction)
        starting = moving & (~self._moving | (new != self.direction))
        for j in np.nonzero(starting)[0]:
            k = (new[j] + 1) // 2
            if self._learned[k, j]:
                if new[j] * (self._memory[k, j] - self.integrator[j]) >= 0.0:
                    self.integrator[j] = self._memory[k, j]
            elif self.direction[j] != 0 and new[j] != self.direction[j]:
                self.integrator[j] = -self.integrator[j]
        self.direction = new
        self._moving = moving

    def _remember_direction(self) -> None:
        """Store the integrator of every moving joint as the one for its direction."""
        for j in np.nonzero(self._moving)[0]:
            k = (self.direction[j] + 1) // 2
            self._memory[k, j] = self.integrator[j]
            self._learned[k, j] = True

    def attach(self, add_periodic: Callable[[float, Callable[[float], None]], object]) -> object:
        """Register :meth:`update` at this rate: ``servo.attach(world.add_periodic)``."""
        return add_periodic(self.dt, self.update)

    def state(self) -> dict[str, np.ndarray]:
        """Observable state of the last update (copies), for logging and tests."""
        return {
            "desired": self.setpoint_jp(),
            "measured": self.measured.copy(),
            "estimate": self.estimate.copy(),
            "error": self.error.copy(),
            "integrator": self.integrator.copy(),
            "correction": self.correction.copy(),
            "commanded": self.commanded.copy(),
            "offset_estimate": self.offset_estimate.copy(),
        }
