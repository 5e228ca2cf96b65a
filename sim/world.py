"""The simulated world: two PSMs, needle, phantom and endoscope in one pybullet client.

One single-threaded loop (DESIGN.md §4): :meth:`World.step` advances simulated time in
physics ticks of 1/rate (1 kHz by default). In every tick, in this order: the periodic
callbacks due at that tick (registration order), the arms' trajectories/servos/jaws, grasp and
release, the pybullet step (free needle dynamics), the kinematic reset of the arm links and of
a held needle, and the phantom's crossing/strain and tissue-entry bookkeeping (fed by
:class:`~suture_bt.sim.needle_watch.NeedleWatch`). Same scene + seed ⇒ same run.

What skills may see is :attr:`World.task` (the known phantom and needle models), the arms
(``psm1``, ``psm2``) and the camera. Ground truth lives in ``suture_bt.sim.ground_truth``.

Reach (closed-form IK, tip z into the tissue, tip x along the ridge): PSM2 (at −x) reaches the
four entry ports, PSM1 (at +x) the four exit ports, so PSM2 inserts and PSM1 pulls through.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pybullet as pb

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.kinematics import forward_kinematics
from suture_bt.kinematics.psm import GRASP_DEPTH, JAW_CLOSED_THRESHOLD
from suture_bt.sim.camera import StereoEndoscope
from suture_bt.sim.faults import WorldFaults, draw_plant
from suture_bt.sim.grasp import GraspCheck, check_grasp
from suture_bt.sim.joint_offsets import JointOffset
from suture_bt.sim.joint_servo import JointServo, ServoParams
from suture_bt.sim.needle_body import NeedleBody
from suture_bt.sim.needle_watch import NeedleWatch
from suture_bt.sim.phantom_body import PhantomBody
from suture_bt.sim.psm_body import LINK_JAWS, LINK_TIP, PSMBody
from suture_bt.sim.quiet import quiet_fd
from suture_bt.sim.rendering import load_renderer
from suture_bt.sim.scene import SceneConfig, default_scene
from suture_bt.sim.sim_clock import PeriodicCallbacks, SimClock
from suture_bt.sim.simulated_psm import SimulatedPSM
from suture_bt.transforms import invert, make_transform, pose_to_transform

#: SRC base (RCM) poses of the two arms in the world (DESIGN.md §5).
PSM_BASE_POSES = {
    "psm1": ((0.100, 0.1346, 0.1350), (0.6981, -0.5236, -np.pi)),
    "psm2": ((-0.100, 0.1346, 0.1350), (0.6981, 0.5236, -np.pi)),
}
GRAVITY = (0.0, 0.0, -9.81)
#: SRC initial needle pose, resting on the tissue, in the phantom frame (DESIGN.md §5).
SRC_NEEDLE_REST_POSITION = (-0.0208, 0.0562, 0.0717)
#: The needle/phantom bookkeeping (held needle snapped onto its jaw, port crossings, strain)
#: runs every this many physics ticks (250 Hz) and at the end of every ``step``: crossing
#: times are interpolated between updates, and the tip moves ~µm per tick, so nothing is lost,
#: while it costs ~0.8 ms per update on a laptop CPU.
BOOKKEEPING_TICKS = 4
#: Jaw angle at which the blades touch a 0.72 mm wire held GRASP_DEPTH behind the tip.
JAW_ON_NEEDLE = 0.08


def psm_base_frame(arm: str) -> np.ndarray:
    """World pose of an arm's base (RCM) frame."""
    position, rpy = PSM_BASE_POSES[arm]
    return pose_to_transform(position, rpy)


@dataclass(frozen=True)
class KnownTask:
    """What a real system is told about the task: the phantom (with its pose) and the needle."""

    phantom: PhantomModel
    needle: NeedleModel = field(default_factory=NeedleModel)


class World:
    """The whole simulated scene; build it with :meth:`from_scene`."""

    def __init__(self, scene: SceneConfig | None = None, with_camera: bool = True):
        self.scene = scene or default_scene()
        self.client = pb.connect(pb.DIRECT)
        self._closed = False
        try:
            self._build(with_camera)
        except BaseException:
            self.close()  # never leak a pybullet client on a failed build
            raise

    def _build(self, with_camera: bool) -> None:
        if with_camera:
            # Bodies created before the EGL plugin loads are never drawn by it.
            load_renderer(self.client)
        self.dt = 1.0 / self.scene.physics_rate_hz
        self.clock = SimClock(self.dt)
        pb.setGravity(*GRAVITY, physicsClientId=self.client)
        pb.setTimeStep(self.dt, physicsClientId=self.client)
        self.rng = np.random.default_rng(self.scene.seed)
        self.task = KnownTask(PhantomModel(self.scene.phantom.T_world_phantom))
        self._periodics = PeriodicCallbacks(self.clock)
        self._target_time = 0.0
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
            servo = JointServo(q_true, params, draw_plant(self.scene, arm))
            body = PSMBody(self.client, psm_base_frame(arm), q_true, name=arm)
            self.arms[arm] = SimulatedPSM(arm, body, servo, offset, self.clock)
        self.psm1 = self.arms["psm1"]
        self.psm2 = self.arms["psm2"]
        self.camera: StereoEndoscope | None = None
        self.needle: NeedleBody | None = None
        self.phantom: PhantomBody | None = None
        self.needle_holders: list[str] = []
        self.last_grasp: dict[str, GraspCheck] = {}
        self._jaw_was_closed = {
            a: arm.jaw.measured_jp()[0] <= JAW_CLOSED_THRESHOLD for a, arm in self.arms.items()
        }
        self._build_task_bodies(with_camera)
        #: Faults (scene-driven and forced by tests): see :mod:`suture_bt.sim.faults`.
        self.faults = WorldFaults(self)

    @classmethod
    def from_scene(cls, scene: SceneConfig | None = None, with_camera: bool = True) -> World:
        """A world built from a scene (``None``: the embedded SRC scene).

        ``with_camera=False`` skips the endoscope (and the EGL plugin), for fast headless tests.
        """
        return cls(scene, with_camera)

    # ------------------------------------------------------------------ task bodies
    def _build_task_bodies(self, with_camera: bool) -> None:
        """Phantom, needle and endoscope."""
        cam = self.scene.camera
        if with_camera:
            self.camera = StereoEndoscope(
                self.client,
                cam.width,
                cam.height,
                cam.noise_std,
                cam.brightness,
                rng=np.random.default_rng([self.scene.seed, 11]),
            )
            self.camera.set_clock(self.clock.now)
        self.phantom = PhantomBody(self.client, self.task.phantom, self.task.needle)
        tissue_ids = (self.phantom.id,)
        T_needle = self._needle_start_pose()
        self.needle = NeedleBody(self.client, self.task.needle, T_needle, tissue_ids)
        for arm in self.arms.values():
            self.needle.ignore_collisions_with(arm.body.body)
        # A needle at rest on the tissue may sleep (Bullet deactivation): contacts of a resting
        # needle otherwise dominate the physics cost. Grasp and release wake it.
        pb.changeDynamics(
            self.needle.id,
            -1,
            activationState=pb.ACTIVATION_STATE_ENABLE_SLEEPING,
            physicsClientId=self.client,
        )
        if self.scene.needle.start == "in_psm2_jaw":
            self.psm2.jaw.servo_jp(0.0)
            self._attach("psm2", self.in_jaw_grasp_pose())
        elif self.phantom.inserted(T_needle):
            # A needle that starts stuck in the tissue is held there.
            self.needle.freeze(T_needle)
        # The phantom's bookkeeping (crossings, strain, tissue entries), fed from the needle.
        self._watch = NeedleWatch(self.client, self.task.phantom, self.task.needle)
        self._watch.start(self.needle, self.phantom)

    def _needle_start_pose(self) -> np.ndarray:
        """World pose of the needle at start, per the scene."""
        nd = self.scene.needle
        if nd.start == "pose":
            return nd.T_world_needle
        if nd.start == "resting":
            return self.task.phantom.T_world_phantom @ pose_to_transform(
                SRC_NEEDLE_REST_POSITION, (0.0, 0.0, 0.0)
            )
        return self.psm2.body.tip_pose() @ self.in_jaw_grasp_pose()

    def in_jaw_grasp_pose(self) -> np.ndarray:
        """Needle pose in the tip frame for a grasp at the scene's arc angle.

        The jaws are orthogonal to the needle plane (needle z = −tip z), the wire runs along the
        tip x axis between the blades (which close along tip y; direction of travel of the tip =
        −tip x, arc centre toward +tip y), ``GRASP_DEPTH`` behind the tip. With this hand, PSM2
        can drive the needle along the planned arc of every SRC port pair.
        """
        a = np.deg2rad(self.scene.needle.grasp_arc_angle_deg)
        tangent = np.array([np.sin(a), -np.cos(a), 0.0])
        radial = np.array([np.cos(a), np.sin(a), 0.0])
        # Rows: tip axes x, y, z expressed in the needle frame (R maps needle -> tip).
        R = np.stack([-tangent, radial, [0.0, 0.0, -1.0]])
        grasp_point = np.array([0.0, 0.0, -GRASP_DEPTH])
        return make_transform(R, grasp_point - R @ self.task.needle.point_at(a))

    @property
    def needle_holder(self) -> str | None:
        """The arm the needle is rigidly attached to (the latest grasp), or None."""
        return self.needle_holders[-1] if self.needle_holders else None

    def _attach(self, arm: str, T_tip_needle: np.ndarray) -> None:
        """Hold the needle rigidly in ``arm``'s jaw at ``T_tip_needle`` (tip frame).

        During a handover both jaws hold the needle; it is attached to the latest grasp and
        passes back to the other arm, where it is, when the latest one opens.
        """
        self._wake_needle()
        self.needle.attach(self.arms[arm].body.body, LINK_TIP, T_tip_needle)
        if arm in self.needle_holders:
            self.needle_holders.remove(arm)
        self.needle_holders.append(arm)
        jaw = self.arms[arm].jaw
        jaw.min_angle = JAW_ON_NEEDLE
        jaw._angle = max(jaw._angle, JAW_ON_NEEDLE)  # the blades rest on the wire

    def _wake_needle(self) -> None:
        pb.changeDynamics(
            self.needle.id,
            -1,
            activationState=pb.ACTIVATION_STATE_WAKE_UP,
            physicsClientId=self.client,
        )

    def _release(self, arm: str) -> None:
        """``arm`` opens its jaw on the needle."""
        self.arms[arm].jaw.min_angle = 0.0
        self.needle.update()  # release from the exact in-hand pose
        was_attached = self.needle_holder == arm
        self.needle_holders.remove(arm)
        if not was_attached:
            return
        if self.needle_holders:
            other = self.needle_holders.pop()
            self._attach(other, invert(self._true_tip_pose(other)) @ self.needle.pose())
        else:
            T = self.needle.pose()
            if self.phantom.inserted(T):
                self.needle.freeze(T)  # the tissue holds an inserted needle that is released
            else:
                self.needle.detach()
                self._wake_needle()

    # ------------------------------------------------------------------ time
    def add_periodic(self, period: float, callback: Callable[[float], None]) -> object:
        """Call ``callback(t)`` every ``period`` s of simulated time, from the next tick on.

        ``period`` must be a whole number of physics ticks (e.g. 0.002-0.005 s at 1 kHz).
        Callbacks due in the same tick run in registration order, before the arms move.
        """
        return self._periodics.add(period, callback)

    def remove_periodic(self, handle: object) -> None:
        """Stop a periodic callback (unknown handles are an error)."""
        self._periodics.remove(handle)

    def step(self, duration: float) -> None:
        """Advance simulated time by ``duration`` seconds (rounded to whole physics ticks)."""
        if self._closed:
            raise RuntimeError("world is closed")
        if not np.isfinite(duration) or duration < 0:
            raise ValueError(f"step duration must be a finite non-negative time, got {duration!r}")
        self._target_time += duration
        n = int(round(self._target_time / self.dt)) - self.clock.ticks
        for i in range(max(0, n)):
            self._tick(last=i == n - 1)

    def _tick(self, last: bool = True) -> None:
        self.clock.ticks += 1
        tick = self.clock.ticks
        t = tick * self.dt
        self._periodics.run_due(tick, t)
        for arm in self.arms.values():
            arm.update(t, self.dt)
        self._grasp_and_release()
        pb.stepSimulation(physicsClientId=self.client)
        for arm in self.arms.values():
            arm.sync_body()
        if last or tick % BOOKKEEPING_TICKS == 0:
            self._after_physics(t)
            if self.faults.active:  # never with no faults: the world runs as without them
                self.faults.tick(t)

    def _grasp_and_release(self) -> None:
        """Release when a holding jaw is commanded open; try a grasp when a jaw closes."""
        if self.needle is None:
            return
        for name, arm in self.arms.items():
            closed = arm.jaw.measured_jp()[0] <= JAW_CLOSED_THRESHOLD
            if name in self.needle_holders and arm.jaw.goal > JAW_CLOSED_THRESHOLD:
                self._release(name)
            elif closed and not self._jaw_was_closed[name] and name not in self.needle_holders:
                grasp = self._grasp_check(name)
                if grasp is not None:
                    self._attach(name, grasp)
            self._jaw_was_closed[name] = closed

    def _grasp_check(self, arm: str) -> np.ndarray | None:
        """In-hand pose (tip frame) when the needle wire lies between the jaws, else None.

        The geometry (and its tolerances) is :func:`suture_bt.sim.grasp.check_grasp`; the
        outcome is kept in :attr:`last_grasp` (simulation side, for logs and tests).
        """
        self.needle.update()  # exact needle pose first
        result = check_grasp(
            self._true_tip_pose(arm),
            float(self.arms[arm].jaw.measured_jp()[0]),
            self.needle.pose(),
            self.task.needle,
        )
        self.last_grasp[arm] = result
        return result.T_tip_needle if result.ok else None

    def _after_physics(self, t: float) -> None:
        """Held needle snaps onto its jaw; the phantom records crossings, strain and entries.

        Runs every ``BOOKKEEPING_TICKS`` physics ticks and at the end of every :meth:`step`
        (between, the grasp constraint carries a held needle within ~0.1 mm of its jaw).
        """
        if self.needle is not None:
            self.needle.update()  # a held needle snaps exactly onto its jaw
            self._watch.update(self.needle, self.phantom, t)

    # ------------------------------------------------------------------ helpers
    def segmentation_masks(self, eye: str = "left") -> dict[str, np.ndarray]:
        """Noise-free render of one eye as boolean masks per object (ground truth).

        Keys: "needle", "psm1", "psm2", "psm1_jaws", "psm2_jaws" and "phantom" (when present).
        """
        if self.camera is None:
            raise RuntimeError("this world was built without a camera")
        view = self.camera.render(eye, with_segmentation=True)
        masks = {}
        if self.needle is not None:
            masks["needle"] = view.mask(self.needle.id)
        for name, arm in self.arms.items():
            masks[name] = view.mask(arm.body.body)
            masks[f"{name}_jaws"] = view.mask(arm.body.body, LINK_JAWS[0]) | view.mask(
                arm.body.body, LINK_JAWS[1]
            )
        if self.phantom is not None:
            masks["phantom"] = view.mask(self.phantom.id)
        return masks

    def _true_tip_pose(self, arm: str) -> np.ndarray:
        """World pose of an arm's true tip (private: ``ground_truth`` hands it out)."""
        a = self.arms[arm]
        return a.base_frame() @ forward_kinematics(a._true_jp())

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if not self._closed:
            self._closed = True
            with quiet_fd(1):  # the EGL plugin prints a banner on disconnect
                pb.disconnect(physicsClientId=self.client)

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
