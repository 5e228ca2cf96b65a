"""Faults in the simulated world: grasp slip, needle drop, lost/dark frames, lighting, drift.

Why: the tree must notice and recover from what goes wrong on a real robot, so the world
makes those things happen honestly (in the physics, the images and the joints, never as
flags a skill could read) and reproducibly (every draw comes from the scene seed, one stream
per kind: same scene + seed ⇒ same faults).

``world.faults`` (a :class:`WorldFaults`) is built from the scene's ``faults:`` section
(:mod:`suture_bt.sim.fault_config`) and is also the API tests use to force a fault, now
(``at=None``) or at a simulated time ``at``:

=========================================================  ====================================
``slip(arm=None, angle_deg=3.0, slide_mm=1.0, at=None)``    needle turns about the jaw's closing
                                                            axis and slides along its wire
``drop(arm=None, at=None)``                                 jaw loses the needle; it falls
``lose_frames(n=1, at=None)``                               next n captures raise ``FrameLost``
``darken(frames=1, brightness=0.25, at=None)``              next captures come back darker
``change_lighting(duration_s, brightness=0.6, ...)``        gain and light tilt for a while
``drift(arm, dq=(deg, deg, mm), duration_s=0.0, at=None)``  hidden Δq ramps by dq (≤ 0.5°, mm)
=========================================================  ====================================

``arm=None`` means the arm the needle is attached to. A slip or drop due while no arm holds the
needle waits until one does (forcing one *now* with nothing held raises ``RuntimeError``).
Every fault that fired is a :class:`FaultEvent` in :attr:`WorldFaults.fired`, read through
``GroundTruth.fault_events()`` (evaluation and tests only: skills must not see it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from suture_bt.kinematics.psm import GRASP_DEPTH
from suture_bt.sim.camera import CaptureFault, light_direction
from suture_bt.sim.fault_config import FAULT_KINDS, MAX_DRIFT_DEG, MAX_DRIFT_MM, FaultConfig
from suture_bt.sim.joint_servo import JointPlant
from suture_bt.transforms import invert, make_transform

#: A holding arm counts as moving above this true joint speed (rad/s or m/s).
MOVING_SPEED = 0.005
#: A slide never leaves less than this arc (rad) between the held point and a needle end.
END_MARGIN = 0.05


@dataclass(frozen=True)
class FaultEvent:
    """One fault that fired: kind, simulated time, source (random/schedule/api), arm, values."""

    kind: str
    time: float
    source: str
    arm: str | None = None
    params: dict[str, Any] = field(default_factory=dict)


def draw_plant(scene, arm: str) -> JointPlant | None:
    """This arm's per-joint servo plant drawn from ``scene.faults.servo`` (None: no ranges)."""
    ranges = scene.faults.servo
    if ranges is None or not scene.servo.error_model:
        return None
    rng = np.random.default_rng([scene.seed, 23, ("psm1", "psm2").index(arm)])

    def u(r: tuple[float, float]) -> np.ndarray:
        return rng.uniform(r[0], r[1], 6)

    bw, zeta = u(ranges.bandwidth_hz), u(ranges.damping_ratio)
    rev = np.deg2rad(u(ranges.revolute_friction_deg))
    pri = u(ranges.prismatic_friction_mm) * 1e-3
    load = u(ranges.load_scale)
    scale = np.where(np.arange(6) == 2, pri, rev)
    return JointPlant(*(tuple(float(v) for v in a) for a in (bw, zeta, scale, load)))


@dataclass
class _Due:
    at: float
    kind: str
    params: dict[str, Any]
    source: str


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


class WorldFaults:
    """The faults of one world: scene-driven draws, forced faults, and the record of both."""

    def __init__(self, world) -> None:
        self._world = world
        self.config: FaultConfig = world.scene.faults
        seed = world.scene.seed
        self._rng = {k: np.random.default_rng([seed, 29, i]) for i, k in enumerate(FAULT_KINDS)}
        #: Every fault that fired, in order (ground truth: read via ``GroundTruth``).
        self.fired: list[FaultEvent] = []
        self._due: list[_Due] = [
            _Due(e.at, e.kind, dict(e.params), "schedule") for e in self.config.schedule
        ]
        self._lost: list[str] = []  # source of each next lost capture
        self._dark: list[tuple[float, str]] = []  # (gain, source) of the next dark captures
        self._light: tuple[float, float, float, tuple[float, float, float]] | None = None
        self._ramps: list[list] = []  # [arm, t0, duration, delta (6), fraction applied]
        c = self.config
        self._rates = {
            "slip": c.slip.rate_per_s,
            "drop": c.drop.rate_per_s,
            "lighting": c.lighting.rate_per_s,
            "drift": c.drift.rate_per_s,
        }
        self._budget = {k: self._draw_wait(k) for k in self._rates}
        self._last_t = world.clock.now()
        self._entries_seen = len(world.phantom.tissue_entries) if world.phantom else 0
        for arm, a in world.arms.items():
            if c.servo is not None and world.scene.servo.error_model:
                self._record("servo_model", "random", arm, **a._servo.plant.as_dict())
        if world.camera is not None:
            world.camera.fault_hook = self._on_capture
        self._refresh()

    # ------------------------------------------------------------------ forcing faults
    def slip(
        self,
        arm: str | None = None,
        angle_deg: float = 3.0,
        slide_mm: float = 1.0,
        at: float | None = None,
    ) -> FaultEvent | None:
        """The needle turns by ``angle_deg`` about the jaw's closing axis (tip y, through the
        held point) and slides ``slide_mm`` along its wire (> 0: the held point moves toward
        the needle tip, as when tissue pushes the needle back). Returns the event when now."""
        return self._force("slip", at, arm=arm, angle_deg=angle_deg, slide_mm=slide_mm)

    def drop(self, arm: str | None = None, at: float | None = None) -> FaultEvent | None:
        """The jaw loses the needle (it stays closed, on nothing); the needle falls, or the
        tissue holds it when it is inserted; during a handover the other jaw keeps it."""
        return self._force("drop", at, arm=arm)

    def lose_frames(self, n: int = 1, at: float | None = None) -> FaultEvent | None:
        """The next ``n`` captures raise :class:`~suture_bt.interfaces.FrameLost`."""
        if int(n) != n or n < 1:
            raise ValueError(f"lose_frames: n must be a positive integer, got {n!r}")
        return self._force("frame_lost", at, frames=int(n))

    def darken(
        self, frames: int = 1, brightness: float = 0.25, at: float | None = None
    ) -> FaultEvent | None:
        """The next ``frames`` captures come back with their RGB scaled by ``brightness``."""
        if int(frames) != frames or frames < 1 or not 0 < brightness <= 1:
            got = f"{frames}, {brightness}"
            raise ValueError(f"darken: need frames >= 1 and 0 < brightness <= 1, got {got}")
        return self._force("dark", at, frames=int(frames), brightness=float(brightness))

    def change_lighting(
        self,
        duration_s: float,
        brightness: float = 0.6,
        tilt_deg: float = 0.0,
        azimuth_deg: float = 0.0,
        at: float | None = None,
    ) -> FaultEvent | None:
        """For ``duration_s``: image gain ``brightness`` and the light tilted ``tilt_deg`` from
        overhead toward world azimuth ``azimuth_deg``."""
        if not duration_s > 0 or not brightness > 0:
            raise ValueError("change_lighting: duration_s and brightness must be positive")
        p = dict(duration_s=duration_s, brightness=brightness, tilt_deg=tilt_deg)
        return self._force("lighting", at, azimuth_deg=azimuth_deg, **p)

    def drift(
        self, arm: str, dq=(0.3, 0.3, 0.3), duration_s: float = 0.0, at: float | None = None
    ) -> FaultEvent | None:
        """The hidden offset Δq of ``arm`` ramps by ``dq`` (deg, deg, mm) over ``duration_s``."""
        dq = tuple(float(v) for v in dq)
        bounds = (MAX_DRIFT_DEG, MAX_DRIFT_DEG, MAX_DRIFT_MM)
        if len(dq) != 3 or any(abs(v) > b for v, b in zip(dq, bounds, strict=True)):
            raise ValueError(f"drift: dq must be 3 values within ±{bounds}, got {dq}")
        if arm not in self._world.arms or duration_s < 0:
            raise ValueError(f"drift: unknown arm {arm!r} or negative duration")
        return self._force("drift", at, arm=arm, dq=dq, duration_s=float(duration_s))

    def pending(self) -> list[tuple[float, str]]:
        """Faults scheduled but not fired yet, as (time, kind)."""
        return [(d.at, d.kind) for d in self._due]

    # ------------------------------------------------------------------ the world calls these
    def tick(self, t: float) -> None:
        """Advance hazards, ramps and the schedule to simulated time ``t`` (world bookkeeping)."""
        dt, self._last_t = t - self._last_t, t
        w = self._world
        holder = w.needle_holder
        moving = holder is not None and w.arms[holder]._true_speed() > MOVING_SPEED
        for kind in ("slip", "drop", "lighting", "drift"):
            if self._rates[kind] > 0 and (moving or kind in ("lighting", "drift")):
                self._budget[kind] -= dt
                if self._budget[kind] <= 0:
                    self._budget[kind] = self._draw_wait(kind)
                    self._random(kind, t)
        if self.config.slip.on_contact_probability > 0 and w.phantom is not None:
            n = len(w.phantom.tissue_entries)
            for _ in range(n - self._entries_seen):
                rng = self._rng["slip"]
                if holder is not None and rng.random() < self.config.slip.on_contact_probability:
                    self._random("slip", t, contact=True)
            self._entries_seen = n
        for d in [d for d in self._due if d.at <= t + 1e-12]:
            if self._apply(d.kind, d.params, d.source, t):
                self._due.remove(d)
        self._advance_ramps(t)
        self._refresh()

    def _on_capture(self, stamp: float) -> CaptureFault | None:
        """The camera asks before every capture: lost, darkened, re-lit or untouched."""
        for d in [d for d in self._due if d.kind in ("frame_lost", "dark") and d.at <= stamp]:
            self._apply(d.kind, d.params, d.source, stamp)
            self._due.remove(d)
        c = self.config
        if not self._lost and c.frame_lost.probability > 0:
            rng = self._rng["frame_lost"]
            if rng.random() < c.frame_lost.probability:
                lo, hi = c.frame_lost.frames
                self._lost = ["random"] * int(rng.integers(lo, hi + 1))
        if self._lost:
            source = self._lost.pop(0)
            self._record("frame_lost", source, None, stamp, still_lost=len(self._lost))
            return CaptureFault(lost=True, reason="camera frame lost (no image from the sensor)")
        if not self._dark and c.dark.probability > 0:
            rng = self._rng["dark"]
            if rng.random() < c.dark.probability:
                n = int(rng.integers(c.dark.frames[0], c.dark.frames[1] + 1))
                self._dark = [(float(rng.uniform(*c.dark.brightness)), "random")] * n
        gain, light = 1.0, None
        if self._dark:
            gain, source = self._dark.pop(0)
            self._record("dark", source, None, stamp, brightness=gain)
        if self._light is not None:
            t0, t1, g, direction = self._light
            if t0 <= stamp < t1:
                gain, light = gain * g, direction
            elif stamp >= t1:
                self._light = None
        if gain == 1.0 and light is None:
            return None
        return CaptureFault(gain=gain, light_direction=light)

    # ------------------------------------------------------------------ internals
    def _draw_wait(self, kind: str) -> float:
        rate = self._rates[kind]
        return float(self._rng[kind].exponential(1.0 / rate)) if rate > 0 else math.inf

    def _refresh(self) -> None:
        """Whether the world must call :meth:`tick` (no faults: it never does)."""
        self.active = bool(
            self._due
            or self._ramps
            or any(r > 0 for r in self._rates.values())
            or self.config.slip.on_contact_probability > 0
        )

    def _record(
        self, kind: str, source: str, arm: str | None, t: float | None = None, **params
    ) -> FaultEvent:
        ev = FaultEvent(kind, self._world.clock.now() if t is None else t, source, arm, params)
        self.fired.append(ev)
        return ev

    def _force(self, kind: str, at: float | None, **params) -> FaultEvent | None:
        if at is None:
            n = len(self.fired)
            if not self._apply(kind, params, "api", self._world.clock.now()):
                raise RuntimeError(f"{kind}: no arm holds the needle")
            self._refresh()
            return self.fired[-1] if len(self.fired) > n else None
        self._due.append(_Due(float(at), kind, params, "api"))
        self._due.sort(key=lambda d: d.at)
        self._refresh()
        return None

    def _random(self, kind: str, t: float, contact: bool = False) -> None:
        """Draw the values of a random fault and apply it."""
        rng, c = self._rng[kind], self.config
        if kind == "slip":
            sign = 1.0 if contact else float(rng.choice((-1.0, 1.0)))
            p = dict(
                angle_deg=float(rng.uniform(*c.slip.angle_deg) * rng.choice((-1.0, 1.0))),
                slide_mm=sign * float(rng.uniform(*c.slip.slide_mm)),
                cause="tissue contact" if contact else "mid-move",
            )
        elif kind == "drop":
            p = {}
        elif kind == "lighting":
            lt = c.lighting
            p = dict(
                duration_s=float(rng.uniform(*lt.duration_s)),
                brightness=float(rng.uniform(*lt.brightness)),
                tilt_deg=float(rng.uniform(*lt.tilt_deg)),
                azimuth_deg=float(rng.uniform(0.0, 360.0)),
            )
        else:  # drift
            d = c.drift
            bound = np.array([d.max_deg, d.max_deg, d.max_mm])
            p = dict(
                arm=str(rng.choice(("psm1", "psm2"))),
                dq=tuple(float(v) for v in rng.uniform(-1.0, 1.0, 3) * bound),
                duration_s=float(rng.uniform(*d.duration_s)),
            )
        self._apply(kind, p, "random", t)

    def _apply(self, kind: str, p: dict, source: str, t: float) -> bool:
        """Make one fault happen now; False when it cannot yet (slip/drop with nothing held).

        Lost and dark frames are recorded when the captures they spoil happen."""
        w = self._world
        if kind in ("slip", "drop"):
            arm = p.get("arm") or w.needle_holder
            if arm is None or arm not in w.needle_holders:
                return False
            if kind == "drop":
                w._release(arm)
                self._record("drop", source, arm, t)
                return True
            if w.needle_holder != arm:  # held but not attached (handover): wait
                return False
            self._slip_now(arm, p, source, t)
            return True
        if kind == "frame_lost":
            self._lost += [source] * int(p.get("frames", 1))
        elif kind == "dark":
            self._dark = [(float(p.get("brightness", 0.25)), source)] * int(p.get("frames", 1))
        elif kind == "lighting":
            direction = light_direction(p.get("tilt_deg", 0.0), p.get("azimuth_deg", 0.0))
            end = t + float(p["duration_s"])
            self._light = (t, end, float(p.get("brightness", 0.6)), direction)
            self._record("lighting", source, None, t, **p)
        elif kind == "drift":
            dq = tuple(p.get("dq", (0.3, 0.3, 0.3)))
            duration = float(p.get("duration_s", 0.0))
            delta = np.array([math.radians(dq[0]), math.radians(dq[1]), dq[2] * 1e-3, 0, 0, 0])
            self._ramps.append([p["arm"], t, duration, delta, 0.0])
            self._record("drift", source, p["arm"], t, dq=dq, duration_s=duration)
            self._advance_ramps(t)
        else:
            raise ValueError(f"unknown fault kind {kind!r}")
        return True

    def _slip_now(self, arm: str, p: dict, source: str, t: float) -> None:
        """Turn and slide the needle in ``arm``'s jaw (the jaw keeps holding it)."""
        w = self._world
        model = w.task.needle
        T = w.needle.T_link_needle  # tip frame <- needle frame
        pinch = invert(T) @ np.array([0.0, 0.0, -GRASP_DEPTH, 1.0])
        held = math.atan2(pinch[1], pinch[0]) % (2 * math.pi)
        lo, hi = model.tip_angle + END_MARGIN, model.base_angle - END_MARGIN
        new_held = min(hi, max(lo, held - float(p.get("slide_mm", 1.0)) * 1e-3 / model.radius))
        delta = held - new_held
        T1 = T @ make_transform(_rot(2, delta))  # the arc slides through the pinch point
        c = T1[:3, :3] @ model.point_at(new_held) + T1[:3, 3]
        turn = math.radians(float(p.get("angle_deg", 3.0)))
        about_c = make_transform(np.eye(3), c) @ make_transform(_rot(1, turn))
        T2 = about_c @ make_transform(np.eye(3), -c) @ T1
        w._attach(arm, T2)
        self._record(
            "slip",
            source,
            arm,
            t,
            angle_deg=float(p.get("angle_deg", 3.0)),
            slide_mm=delta * model.radius * 1e3,
            held_arc_deg=(math.degrees(held), math.degrees(new_held)),
            **({"cause": p["cause"]} if "cause" in p else {}),
        )

    def _advance_ramps(self, t: float) -> None:
        """Apply the share of every drift ramp due by ``t`` to its arm's hidden offset."""
        for ramp in list(self._ramps):
            arm, t0, duration, delta, done = ramp
            s = 1.0 if duration <= 0 else min(1.0, max(0.0, (t - t0) / duration))
            if s > done:
                psm = self._world.arms[arm]
                psm._set_true_offset(psm._true_offset() + (s - done) * delta)
                ramp[4] = s
            if s >= 1.0:
                self._ramps.remove(ramp)
