"""The simulated world: two PSMs, needle, phantom and endoscope in one pybullet client.

One single-threaded loop (DESIGN.md §4): :meth:`World.step` advances simulated time in
physics ticks of 1/rate (1 kHz by default). In every tick, in this order: the periodic
callbacks due at that tick (registration order), the arms' trajectories/servos/jaws, grasp and
release, the pybullet step (free needle dynamics), the kinematic reset of the arm links and of
a held needle, and the phantom's crossing/strain bookkeeping. Same scene + seed ⇒ same run.

What skills may see is :attr:`World.task` (the known phantom and needle models), the arms
(``psm1``, ``psm2``) and the camera. Ground truth lives in ``suture_bt.sim.ground_truth``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pybullet as pb

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.kinematics import forward_kinematics
from suture_bt.sim.joint_offsets import JointOffset
from suture_bt.sim.joint_servo import JointServo, ServoParams
from suture_bt.sim.psm_body import PSMBody
from suture_bt.sim.scene import SceneConfig, default_scene
from suture_bt.sim.simulated_psm import SimulatedPSM
from suture_bt.transforms import pose_to_transform

#: SRC base (RCM) poses of the two arms in the world (DESIGN.md §5).
PSM_BASE_POSES = {
    "psm1": ((0.100, 0.1346, 0.1350), (0.6981, -0.5236, -np.pi)),
    "psm2": ((-0.100, 0.1346, 0.1350), (0.6981, 0.5236, -np.pi)),
}
GRAVITY = (0.0, 0.0, -9.81)


def psm_base_frame(arm: str) -> np.ndarray:
    """World pose of an arm's base (RCM) frame."""
    position, rpy = PSM_BASE_POSES[arm]
    return pose_to_transform(position, rpy)


@dataclass(frozen=True)
class KnownTask:
    """What a real system is told about the task: the phantom (with its pose) and the needle."""

    phantom: PhantomModel
    needle: NeedleModel = field(default_factory=NeedleModel)


class SimClock:
    """Simulated time, counted in whole physics ticks (no drift)."""

    def __init__(self, dt: float):
        self.dt = dt
        self.ticks = 0

    def now(self) -> float:
        return self.ticks * self.dt


@dataclass
class _Periodic:
    period_ticks: int
    next_tick: int
    callback: Callable[[float], None]
    order: int


class World:
    """The whole simulated scene; build it with :meth:`from_scene`."""

    def __init__(self, scene: SceneConfig | None = None):
        self.scene = scene or default_scene()
        self.client = pb.connect(pb.DIRECT)
        self.dt = 1.0 / self.scene.physics_rate_hz
        self.clock = SimClock(self.dt)
        pb.setGravity(*GRAVITY, physicsClientId=self.client)
        pb.setTimeStep(self.dt, physicsClientId=self.client)
        self.rng = np.random.default_rng(self.scene.seed)
        self.task = KnownTask(PhantomModel(self.scene.phantom.T_world_phantom))
        self._periodics: list[_Periodic] = []
        self._next_order = 0
        self._target_time = 0.0
        self._closed = False
        sv = self.scene.servo
        params = ServoParams(
            sv.bandwidth_hz,
            sv.damping_ratio,
            sv.revolute_friction_deg,
            sv.prismatic_friction_mm,
            sv.gravity_load,
            ideal=not sv.error_model,
        )
        self.arms: dict[str, SimulatedPSM] = {}
        for arm in ("psm1", "psm2"):
            offset = JointOffset(self.scene.joint_offset(arm))
            q_true = offset.actuated(self.scene.arms[arm].initial_jp)
            servo = JointServo(q_true, params)
            body = PSMBody(self.client, psm_base_frame(arm), q_true, name=arm)
            self.arms[arm] = SimulatedPSM(arm, body, servo, offset, self.clock)
        self.psm1 = self.arms["psm1"]
        self.psm2 = self.arms["psm2"]
        self.camera = None
        self.needle = None
        self.phantom = None
        self._build_task_bodies()

    @classmethod
    def from_scene(cls, scene: SceneConfig | None = None) -> World:
        """A world built from a scene (``None``: the embedded SRC scene)."""
        return cls(scene)

    # ------------------------------------------------------------------ B's parts
    def _build_task_bodies(self) -> None:
        """Phantom, needle and endoscope, when their modules exist."""

    # ------------------------------------------------------------------ time
    def add_periodic(self, period: float, callback: Callable[[float], None]) -> object:
        """Call ``callback(t)`` every ``period`` s of simulated time, from the next tick on.

        ``period`` must be a whole number of physics ticks (e.g. 0.002-0.005 s at 1 kHz).
        Callbacks due in the same tick run in registration order, before the arms move.
        """
        ticks = period / self.dt
        if not np.isfinite(ticks) or ticks < 0.999 or abs(ticks - round(ticks)) > 1e-6:
            raise ValueError(
                f"period {period!r} s is not a positive multiple of the physics step {self.dt} s"
            )
        handle = _Periodic(int(round(ticks)), self.clock.ticks + 1, callback, self._next_order)
        self._next_order += 1
        self._periodics.append(handle)
        return handle

    def remove_periodic(self, handle: object) -> None:
        """Stop a periodic callback (unknown handles are an error)."""
        try:
            self._periodics.remove(handle)
        except ValueError:
            raise ValueError("remove_periodic: unknown handle") from None

    def step(self, duration: float) -> None:
        """Advance simulated time by ``duration`` seconds (rounded to whole physics ticks)."""
        if self._closed:
            raise RuntimeError("world is closed")
        if not np.isfinite(duration) or duration < 0:
            raise ValueError(f"step duration must be a finite non-negative time, got {duration!r}")
        self._target_time += duration
        n = int(round(self._target_time / self.dt)) - self.clock.ticks
        for _ in range(max(0, n)):
            self._tick()

    def _tick(self) -> None:
        self.clock.ticks += 1
        tick = self.clock.ticks
        t = tick * self.dt
        for p in list(self._periodics):
            if tick >= p.next_tick and p in self._periodics:
                p.next_tick += p.period_ticks
                p.callback(t)
        for arm in self.arms.values():
            arm.update(t, self.dt)
        self._grasp_and_release()
        pb.stepSimulation(physicsClientId=self.client)
        for arm in self.arms.values():
            arm.sync_body()
        self._after_physics(t)

    def _grasp_and_release(self) -> None:
        """Grasp on jaw closing / release on opening (needs the needle)."""

    def _after_physics(self, t: float) -> None:
        """Held needle follows its jaw; the phantom records crossings and strain."""

    # ------------------------------------------------------------------ helpers
    def true_tip_pose(self, arm: str) -> np.ndarray:
        """World pose of an arm's true tip (ground truth; use ``ground_truth``)."""
        a = self.arms[arm]
        return a.base_frame() @ forward_kinematics(a.true_jp)

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if not self._closed:
            self._closed = True
            pb.disconnect(physicsClientId=self.client)

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
