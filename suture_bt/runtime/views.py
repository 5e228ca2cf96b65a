"""Interface-only views of the simulator's arms, camera and clock (DESIGN.md §3).

The simulator's objects carry ground truth in public attributes (``SimulatedPSM.body``,
``._servo``, ``._true_jp()``, ``World.scene``, ``StereoEndoscope.render()`` ...). Skills get
these views instead: each exposes exactly the methods of its Protocol in
:mod:`suture_bt.interfaces.robot`, keeps the wrapped object only inside a closure (no
attribute, slot or ``vars()`` entry leads back to it), returns copies of arrays and drops the
return values of commands. Views are read-only.

This module wraps any object with the right methods: it imports neither pybullet nor
``suture_bt.sim``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from suture_bt.interfaces import JointState, StereoCameraModel, StereoFrame

ARM_METHODS = (
    "measured_js",
    "measured_jp",
    "measured_jv",
    "setpoint_jp",
    "servo_jp",
    "move_jp",
    "measured_cp",
    "setpoint_cp",
    "servo_cp",
    "move_cp",
    "is_busy",
    "base_frame",
)
JAW_METHODS = ("open", "close", "measured_jp", "setpoint_jp", "move_jp", "servo_jp", "is_busy")
CAMERA_METHODS = ("capture",)
CLOCK_METHODS = ("now",)


def _bind(target: object, names: tuple[str, ...], view: str) -> Callable[[str], Callable]:
    """A closure over the target's bound methods ``names``; the target itself is not kept.

    Raises ``TypeError`` naming what is missing, so a wrong object fails at wiring time.
    """
    missing = [n for n in names if not callable(getattr(target, n, None))]
    if missing:
        raise TypeError(f"{view}: {type(target).__name__} has no {', '.join(missing)}()")
    methods = {n: getattr(target, n) for n in names}

    def method(name: str) -> Callable:
        return methods[name]

    return method


def _copy(a: Any) -> np.ndarray:
    return np.array(a, copy=True)


class _View:
    """Read-only base: views are built once and never re-pointed."""

    __slots__ = ()

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"{type(self).__name__} is read-only")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"{type(self).__name__} is read-only")


class JawView(_View):
    """The jaw of an arm (:class:`~suture_bt.interfaces.JawInterface` plus ``is_busy``)."""

    __slots__ = ("_ops",)

    def __init__(self, jaw: object):
        object.__setattr__(self, "_ops", _bind(jaw, JAW_METHODS, "JawView"))

    def open(self, angle: float | None = None) -> None:
        """Open to ``angle`` (rad), or to the arm's default opening."""
        if angle is None:
            self._ops("open")()
        else:
            self._ops("open")(angle)

    def close(self) -> None:
        self._ops("close")()

    def measured_jp(self) -> np.ndarray:
        return _copy(self._ops("measured_jp")())

    def setpoint_jp(self) -> np.ndarray:
        return _copy(self._ops("setpoint_jp")())

    def move_jp(self, jp) -> None:
        self._ops("move_jp")(jp)

    def servo_jp(self, jp) -> None:
        self._ops("servo_jp")(jp)

    def is_busy(self) -> bool:
        return bool(self._ops("is_busy")())

    def __repr__(self) -> str:
        return "JawView()"


class ArmView(_View):
    """One PSM as skills see it: exactly :class:`~suture_bt.interfaces.PSMInterface`."""

    __slots__ = ("_ops", "_name", "_jaw")

    def __init__(self, psm: object):
        object.__setattr__(self, "_ops", _bind(psm, ARM_METHODS, "ArmView"))
        object.__setattr__(self, "_name", str(psm.name))
        object.__setattr__(self, "_jaw", JawView(psm.jaw))

    @property
    def name(self) -> str:
        return self._name

    @property
    def jaw(self) -> JawView:
        return self._jaw

    def measured_js(self) -> JointState:
        js = self._ops("measured_js")()
        return JointState(_copy(js.position), _copy(js.velocity), _copy(js.effort))

    def measured_jp(self) -> np.ndarray:
        return _copy(self._ops("measured_jp")())

    def measured_jv(self) -> np.ndarray:
        return _copy(self._ops("measured_jv")())

    def setpoint_jp(self) -> np.ndarray:
        return _copy(self._ops("setpoint_jp")())

    def servo_jp(self, jp) -> None:
        self._ops("servo_jp")(jp)

    def move_jp(self, jp) -> None:
        self._ops("move_jp")(jp)

    def measured_cp(self) -> np.ndarray:
        return _copy(self._ops("measured_cp")())

    def setpoint_cp(self) -> np.ndarray:
        return _copy(self._ops("setpoint_cp")())

    def servo_cp(self, cp) -> None:
        self._ops("servo_cp")(cp)

    def move_cp(self, cp) -> None:
        self._ops("move_cp")(cp)

    def is_busy(self) -> bool:
        return bool(self._ops("is_busy")())

    def base_frame(self) -> np.ndarray:
        return _copy(self._ops("base_frame")())

    def __repr__(self) -> str:
        return f"ArmView({self._name!r})"


class CameraView(_View):
    """The stereo endoscope: ``capture()`` and ``model`` only (no renders, no masks)."""

    __slots__ = ("_ops", "_model_of")

    def __init__(self, camera: object):
        object.__setattr__(self, "_ops", _bind(camera, CAMERA_METHODS, "CameraView"))
        model = getattr(camera, "model", None)
        if not isinstance(model, StereoCameraModel):
            raise TypeError(f"CameraView: model is a {type(model).__name__}, not StereoCameraModel")

        def model_of() -> StereoCameraModel:
            return camera.model

        object.__setattr__(self, "_model_of", model_of)

    @property
    def model(self) -> StereoCameraModel:
        """A deep copy: the camera's own model cannot be altered through the view."""
        return copy.deepcopy(self._model_of())

    def capture(self) -> StereoFrame:
        frame = self._ops("capture")()
        return StereoFrame(_copy(frame.left), _copy(frame.right), float(frame.stamp))

    def __repr__(self) -> str:
        return "CameraView()"


class ClockView(_View):
    """Simulated time: ``now()`` in seconds, nothing else."""

    __slots__ = ("_ops",)

    def __init__(self, clock: object):
        object.__setattr__(self, "_ops", _bind(clock, CLOCK_METHODS, "ClockView"))

    def now(self) -> float:
        return float(self._ops("now")())

    def __repr__(self) -> str:
        return "ClockView()"


@dataclass(frozen=True, slots=True)
class WorldViews:
    """The views of one world that skills may be handed (``camera`` is None without one)."""

    psm1: ArmView
    psm2: ArmView
    camera: CameraView | None
    clock: ClockView

    @property
    def arms(self) -> dict[str, ArmView]:
        return {"psm1": self.psm1, "psm2": self.psm2}


def views_of(world: object) -> WorldViews:
    """Interface-only views of ``world.psm1``, ``world.psm2``, ``world.camera``, ``world.clock``."""
    camera = getattr(world, "camera", None)
    return WorldViews(
        psm1=ArmView(world.psm1),
        psm2=ArmView(world.psm2),
        camera=None if camera is None else CameraView(camera),
        clock=ClockView(world.clock),
    )


__all__ = ["ArmView", "CameraView", "ClockView", "JawView", "WorldViews", "views_of"]
