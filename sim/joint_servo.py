"""Low-level joint servo of one PSM: a PD controller driving a loaded, frictional plant at 1 kHz.

Why: the real dVRK's joint controllers do not reach their set-points (seed paper; SRC issue
#64). The high-level PI loop must remove that error, so the simulation produces it the way
hardware does, from load and friction acting against a finite-gain controller, never as a
constant added to the output.

Model, per joint i (all quantities per unit inertia, so "torque" is an acceleration)::

    q̈ = Kp·(q_sp − q) − Kd·q̇ − g_i(q) − f_c·sign(q̇)        (stuck while |drive| ≤ f_c)

* ``Kp = ω²``, ``Kd = 2ζω`` with ω = 2π·bandwidth_hz (default 6 Hz, ζ = 1): the closed loop
  is a critically damped second-order system with about 6 Hz bandwidth.
* Coulomb friction ``f_c = Kp·e_f`` with ``e_f`` = ``revolute_friction_deg`` (1.5°) or
  ``prismatic_friction_mm`` (0.1 mm): stick-slip (Karnopp) — a joint at rest stays at rest
  while the controller's drive ``Kp·e − g`` is below ``f_c``. Approaching a set-point, the drive
  falls below friction and the joint sticks short of it.
* The load ``g_i(q)`` (scaled by ``gravity_load``) is configuration dependent: on the outer
  pitch joint ``0.5·Kp·e_f·cos(q2)·(q3 / 0.15)`` (the tool's weight about the pitch axis grows
  with insertion), on the insertion joint ``0.5·Kp·e_f·cos(q2)·cos(q1)`` (the tool's weight
  along the shaft). Other joints carry friction only.

Resulting steady-state error after a step (measured by ``tests/test_joint_servo.py`` for steps
of 0.1-0.5 rad and 10-50 mm, both directions, at the default parameters): 1.5° on the
friction-only revolute joints (1, 4, 5, 6), 0.9°-2.1° on the loaded outer pitch, 0.05-0.15 mm
on the insertion joint; the joint stops short of the set-point (or is pulled by the load), so
the sign depends on the approach direction. A 1 kHz
semi-implicit Euler integrator is used (ω·dt ≈ 0.04, stable).

``ideal=True`` (scene ``servo.error_model: false``) makes the joints follow the set-point
exactly, for tests that need an exact arm.

"The robot is not the model": a :class:`JointPlant` gives every joint its own bandwidth,
damping, friction and load scale (drawn per run from the scene's ``faults.servo`` ranges by
:func:`suture_bt.sim.faults.draw_plant`); without one, all joints share :class:`ServoParams`
and the arithmetic is exactly that of a single shared plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from suture_bt.kinematics.psm import JOINT_IS_PRISMATIC, JOINT_LIMITS

#: Velocity below which a joint counts as at rest for stick-slip friction (rad/s or m/s).
_STICK_VELOCITY = 1e-4


@dataclass(frozen=True)
class ServoParams:
    """Parameters of the servo model (see the module docstring)."""

    bandwidth_hz: float = 6.0
    damping_ratio: float = 1.0
    revolute_friction_deg: float = 1.5
    prismatic_friction_mm: float = 0.1
    gravity_load: float = 1.0
    ideal: bool = False

    @property
    def error_scale(self) -> np.ndarray:
        """e_f per joint: the position error at which the P-term balances friction."""
        rev = np.deg2rad(self.revolute_friction_deg)
        pri = self.prismatic_friction_mm * 1e-3
        return np.where(JOINT_IS_PRISMATIC, pri, rev)


@dataclass(frozen=True)
class JointPlant:
    """Per-joint plant: bandwidth (Hz), damping ratio, friction e_f (rad or m), load scale."""

    bandwidth_hz: tuple[float, ...]
    damping_ratio: tuple[float, ...]
    error_scale: tuple[float, ...]
    load_scale: tuple[float, ...]

    @classmethod
    def uniform(cls, params: ServoParams) -> JointPlant:
        """Every joint with the shared parameters (the scene's ``servo`` section)."""
        return cls(
            (params.bandwidth_hz,) * 6,
            (params.damping_ratio,) * 6,
            tuple(float(v) for v in params.error_scale),
            (1.0,) * 6,
        )

    def as_dict(self) -> dict[str, list[float]]:
        """Plain lists, for records and JSON."""
        return {k: list(getattr(self, k)) for k in self.__dataclass_fields__}


class JointServo:
    """Six joints driven toward a set-point; ``step(dt)`` integrates one physics step."""

    def __init__(self, q0, params: ServoParams | None = None, plant: JointPlant | None = None):
        self.params = params or ServoParams()
        self.plant = plant or JointPlant.uniform(self.params)
        self.q = np.array(q0, dtype=float)
        self.qd = np.zeros(6)
        self.setpoint = self.q.copy()
        # Per joint, with the same float operations as one shared plant (identical results).
        w = [2 * np.pi * b for b in self.plant.bandwidth_hz]
        self._kp = [x * x for x in w]
        self._kd = [2 * z * x for z, x in zip(self.plant.damping_ratio, w, strict=True)]
        self.kp = np.array(self._kp)
        self.kd = np.array(self._kd)
        self.friction = self.kp * np.array(self.plant.error_scale)
        self.effort = np.zeros(6)
        self._friction = self.friction.tolist()
        s = [0.5 * self.params.gravity_load * x for x in self.plant.load_scale]
        self._load_gain = s if any(x != s[0] for x in s) else None
        self._lo = JOINT_LIMITS[:, 0].tolist()
        self._hi = JOINT_LIMITS[:, 1].tolist()

    def reset(self, q) -> None:
        """Put the joints at rest at q, with the set-point there too."""
        self.q = np.array(q, dtype=float)
        self.qd = np.zeros(6)
        self.setpoint = self.q.copy()

    def load(self, q: np.ndarray) -> np.ndarray:
        """Configuration-dependent load (per unit inertia) on each joint."""
        g = np.zeros(6)
        s1 = s2 = 0.5 * self.params.gravity_load
        if self._load_gain is not None:
            s1, s2 = self._load_gain[1], self._load_gain[2]
        g[1] = s1 * self._friction[1] * math.cos(q[1]) * (q[2] / 0.15)
        g[2] = s2 * self._friction[2] * math.cos(q[1]) * math.cos(q[0])
        return g

    def step(self, dt: float) -> None:
        """Advance the joints by dt toward ``setpoint``."""
        if self.params.ideal:
            self.qd = (self.setpoint - self.q) / dt
            self.q = self.setpoint.copy()
            self.effort = np.zeros(6)
            return
        # Six scalar joints: a plain loop is several times faster than numpy on 6-vectors.
        q, qd, sp = self.q.tolist(), self.qd.tolist(), self.setpoint.tolist()
        load = self.load(self.q).tolist()
        kp, kd = self._kp, self._kd
        q_new, qd_new, effort = [0.0] * 6, [0.0] * 6, [0.0] * 6
        for i in range(6):
            f = self._friction[i]
            drive = kp[i] * (sp[i] - q[i]) - kd[i] * qd[i] - load[i]
            effort[i] = drive
            v = qd[i]
            if abs(v) > _STICK_VELOCITY:
                v_next = v + (drive - f * math.copysign(1.0, v)) * dt
                # Friction cannot reverse the motion within one step: stop there instead.
                if (v_next > 0.0) != (v > 0.0) and abs(drive) <= f:
                    v_next = 0.0
            elif abs(drive) <= f:
                v_next = 0.0  # stuck: static friction holds the joint
            else:
                v_next = v + (drive - math.copysign(f, drive)) * dt
            x = q[i] + v_next * dt
            # The joint stops at its mechanical limits.
            if x < self._lo[i]:
                x, v_next = self._lo[i], 0.0
            elif x > self._hi[i]:
                x, v_next = self._hi[i], 0.0
            q_new[i], qd_new[i] = x, v_next
        self.q = np.array(q_new)
        self.qd = np.array(qd_new)
        self.effort = np.array(effort)
