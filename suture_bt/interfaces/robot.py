"""Robot interface (CRTK names as on the dVRK), stereo camera and clock, as Protocols.

Everything is in SI units. Cartesian poses are 4×4 homogeneous transforms of the tool tip in
the arm's base (RCM) frame, as the dVRK reports them; ``base_frame()`` gives that frame in
the world. Commands never block: ``move_*`` start an interpolated motion that advances as
simulated time advances; ``servo_*`` set the low-level setpoint directly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from suture_bt.interfaces.camera_model import StereoCameraModel


@dataclass(frozen=True)
class JointState:
    """CRTK joint state: position (rad / m), velocity, effort."""

    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


@runtime_checkable
class JawInterface(Protocol):
    """The PSM jaw: one revolute DoF, 0 (closed) to 1.57 rad (open)."""

    def open(self, angle: float = ...) -> None: ...
    def close(self) -> None: ...
    def measured_jp(self) -> np.ndarray: ...
    def setpoint_jp(self) -> np.ndarray: ...
    def move_jp(self, jp) -> None: ...
    def servo_jp(self, jp) -> None: ...


@runtime_checkable
class PSMInterface(Protocol):
    """One Patient Side Manipulator. Measured values are what the encoders report."""

    name: str
    jaw: JawInterface

    def measured_js(self) -> JointState: ...
    def measured_jp(self) -> np.ndarray: ...
    def measured_jv(self) -> np.ndarray: ...
    def setpoint_jp(self) -> np.ndarray: ...
    def servo_jp(self, jp) -> None: ...
    def move_jp(self, jp) -> None: ...
    def measured_cp(self) -> np.ndarray: ...
    def setpoint_cp(self) -> np.ndarray: ...
    def servo_cp(self, cp) -> None: ...
    def move_cp(self, cp) -> None: ...
    def is_busy(self) -> bool: ...
    def base_frame(self) -> np.ndarray: ...


@dataclass(frozen=True)
class StereoFrame:
    """One synchronised capture: RGB uint8 images (H×W×3) and the simulated time it was taken."""

    left: np.ndarray
    right: np.ndarray
    stamp: float


class FrameLost(RuntimeError):
    """``capture()`` got no frame this time (dropped or corrupt); nothing is wrong with the scene.

    Why an exception: a lost frame has no images, and a caller that ignores the failure must
    not go on with stale or empty arrays. ``reason`` says what happened, ``stamp`` is the
    (simulated) time of the failed capture. Capturing again later may succeed; a darkened or
    re-lit frame is *not* lost (it comes back as a normal, darker :class:`StereoFrame`).
    """

    def __init__(self, reason: str = "frame lost", stamp: float = 0.0):
        super().__init__(f"{reason} (at t = {stamp:.3f} s)")
        self.reason = reason
        self.stamp = float(stamp)

    def __reduce__(self):
        return (type(self), (self.reason, self.stamp))


@runtime_checkable
class StereoCameraInterface(Protocol):
    """The stereo endoscope: images plus the (known, calibrated) camera model.

    ``capture()`` returns both eyes, or raises :class:`FrameLost` when the frame is lost.
    """

    def capture(self) -> StereoFrame: ...
    @property
    def model(self) -> StereoCameraModel: ...


@runtime_checkable
class Clock(Protocol):
    """Simulated time in seconds."""

    def now(self) -> float: ...


@runtime_checkable
class WorldInterface(Protocol):
    """What the runtime drives: arms, camera, clock and the passage of simulated time.

    ``add_periodic`` registers a callback (e.g. the high-level PI servo) that the world calls
    every ``period`` seconds of simulated time while ``step`` advances it.
    """

    psm1: PSMInterface
    psm2: PSMInterface
    camera: StereoCameraInterface
    clock: Clock

    def step(self, duration: float) -> None: ...
    def add_periodic(self, period: float, callback: Callable[[float], None]) -> object: ...
    def remove_periodic(self, handle: object) -> None: ...
