"""The ``faults:`` section of a scene file: seeded fault rates, servo ranges and a schedule.

Why: recovery can only be built and measured against faults the world produces honestly and
reproducibly. This module only validates and freezes the section (one-line
:class:`~suture_bt.sim.scene_fields.SceneError` per problem); :mod:`suture_bt.sim.faults`
makes them happen. A section is either a profile name (``faults: mild``; profiles live in
``fault_profiles.yaml``) or a mapping; a mapping may start from a profile (``profile: mild``)
and override any of its kinds::

    faults:
      profile: none
      servo: {bandwidth_hz: [3, 12], revolute_friction_deg: [0.5, 2.5]}
      slip: {rate_per_s: 0.01, on_contact_probability: 0.1, angle_deg: [1, 5], slide_mm: [0.3, 1.5]}
      schedule:
        - {at: 12.0, kind: drop}
        - {at: 3.0, kind: frame_lost, frames: 2}

Units follow the key names (``_deg``, ``_mm``, ``_s``); rates are per second of simulated time
(slip and drop: per second during which a holding arm moves), probabilities per capture.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from typing import Any

import yaml

from suture_bt.sim.scene_fields import (
    SceneError,
    _fail,
    _int_range,
    _mapping,
    _non_negative,
    _number,
    _positive,
    _positive_int,
    _probability,
    _range,
    _vector,
)

Range = tuple[float, float]
#: Largest joint-offset drift of one drift fault (deg on joints 1-2, mm on joint 3).
MAX_DRIFT_DEG = 0.5
MAX_DRIFT_MM = 0.5
FAULT_KINDS = ("slip", "drop", "frame_lost", "dark", "lighting", "drift")
ARMS = ("psm1", "psm2")


@dataclass(frozen=True)
class ServoRanges:
    """Ranges the low-level servo model is drawn from, uniformly, per run, arm and joint."""

    bandwidth_hz: Range = (6.0, 6.0)
    damping_ratio: Range = (1.0, 1.0)
    revolute_friction_deg: Range = (1.5, 1.5)
    prismatic_friction_mm: Range = (0.1, 0.1)
    load_scale: Range = (1.0, 1.0)


@dataclass(frozen=True)
class SlipSpec:
    """Grasp slip: hazard while a holding arm moves, and a chance per tissue contact."""

    rate_per_s: float = 0.0
    on_contact_probability: float = 0.0
    angle_deg: Range = (1.0, 5.0)
    slide_mm: Range = (0.3, 1.5)


@dataclass(frozen=True)
class DropSpec:
    """Needle drop: hazard while a holding arm moves."""

    rate_per_s: float = 0.0


@dataclass(frozen=True)
class FrameSpec:
    """Lost or darkened captures: chance per capture, and how many captures in a row."""

    probability: float = 0.0
    frames: tuple[int, int] = (1, 1)
    brightness: Range = (0.15, 0.4)  # dark only


@dataclass(frozen=True)
class LightingSpec:
    """Lighting change for a while: brightness gain and light tilt from overhead."""

    rate_per_s: float = 0.0
    duration_s: Range = (2.0, 6.0)
    brightness: Range = (0.6, 1.4)
    tilt_deg: Range = (0.0, 30.0)


@dataclass(frozen=True)
class DriftSpec:
    """Joint-offset drift: hazard per second; each drift ramps Δq by a drawn amount."""

    rate_per_s: float = 0.0
    max_deg: float = MAX_DRIFT_DEG
    max_mm: float = MAX_DRIFT_MM
    duration_s: Range = (1.0, 5.0)


@dataclass(frozen=True)
class ScheduledFault:
    """One fault at a simulated time; ``params`` as sorted (key, value) pairs (hashable)."""

    at: float
    kind: str
    params: tuple[tuple[str, Any], ...] = ()

    def param(self, key: str, default: Any = None) -> Any:
        return dict(self.params).get(key, default)


@dataclass(frozen=True)
class FaultConfig:
    """The whole ``faults:`` section; ``FaultConfig()`` is no faults at all."""

    profile: str = "none"
    servo: ServoRanges | None = None
    slip: SlipSpec = SlipSpec()
    drop: DropSpec = DropSpec()
    frame_lost: FrameSpec = FrameSpec()
    dark: FrameSpec = FrameSpec()
    lighting: LightingSpec = LightingSpec()
    drift: DriftSpec = DriftSpec()
    schedule: tuple[ScheduledFault, ...] = ()

    @property
    def any(self) -> bool:
        """True when this section can produce any fault (or draws the servo)."""
        return self != FaultConfig(profile=self.profile)


# --------------------------------------------------------------------------- profiles


def profile_names() -> tuple[str, ...]:
    """Names of the shipped profiles (``fault_profiles.yaml``)."""
    return tuple(_profiles())


def _profiles() -> dict:
    text = resources.files("suture_bt.sim").joinpath("fault_profiles.yaml").read_text()
    return yaml.safe_load(text)


def profile(name: str) -> FaultConfig:
    """A shipped profile by name (``none``, ``mild``, ``harsh``)."""
    return parse_faults(name)


# --------------------------------------------------------------------------- parsing


def _rate(m: dict, key: str, path: str) -> float:
    return _non_negative(m[key], f"{path}.{key}")


def _servo(raw: Any, path: str) -> ServoRanges:
    d = ServoRanges()
    m = _mapping(raw, path, tuple(d.__dataclass_fields__))
    hi = {"bandwidth_hz": 50.0, "damping_ratio": 5.0, "load_scale": 5.0}
    lo = {"bandwidth_hz": 0.5, "damping_ratio": 0.1}
    out = {}
    for key in d.__dataclass_fields__:
        if key in m:
            out[key] = _range(m[key], f"{path}.{key}", lo.get(key, 0.0), hi.get(key, 100.0))
    return ServoRanges(**out)


def _slip(raw: Any, path: str, base: SlipSpec) -> SlipSpec:
    m = _mapping(raw, path, tuple(SlipSpec.__dataclass_fields__))
    out = {}
    if "rate_per_s" in m:
        out["rate_per_s"] = _rate(m, "rate_per_s", path)
    if "on_contact_probability" in m:
        p = f"{path}.on_contact_probability"
        out["on_contact_probability"] = _probability(m["on_contact_probability"], p)
    if "angle_deg" in m:
        out["angle_deg"] = _range(m["angle_deg"], f"{path}.angle_deg", 0.0, 45.0)
    if "slide_mm" in m:
        out["slide_mm"] = _range(m["slide_mm"], f"{path}.slide_mm", 0.0, 10.0)
    return SlipSpec(**{**base.__dict__, **out})


def _drop(raw: Any, path: str, base: DropSpec) -> DropSpec:
    m = _mapping(raw, path, ("rate_per_s",))
    return DropSpec(_rate(m, "rate_per_s", path)) if "rate_per_s" in m else base


def _frames(raw: Any, path: str, base: FrameSpec, dark: bool) -> FrameSpec:
    keys = ("probability", "frames", "brightness") if dark else ("probability", "frames")
    m = _mapping(raw, path, keys)
    out = {}
    if "probability" in m:
        out["probability"] = _probability(m["probability"], f"{path}.probability")
    if "frames" in m:
        out["frames"] = _int_range(m["frames"], f"{path}.frames")
    if "brightness" in m:
        b = _range(m["brightness"], f"{path}.brightness", 0.0, 1.0)
        if b[0] <= 0:
            _fail(f"{path}.brightness", "[low, high] with 0 < low <= high <= 1", m["brightness"])
        out["brightness"] = b
    return FrameSpec(**{**base.__dict__, **out})


def _lighting(raw: Any, path: str, base: LightingSpec) -> LightingSpec:
    m = _mapping(raw, path, tuple(LightingSpec.__dataclass_fields__))
    out = {}
    if "rate_per_s" in m:
        out["rate_per_s"] = _rate(m, "rate_per_s", path)
    if "duration_s" in m:
        out["duration_s"] = _range(m["duration_s"], f"{path}.duration_s", 0.0, 600.0)
    if "brightness" in m:
        b = _range(m["brightness"], f"{path}.brightness", 0.0, 4.0)
        if b[0] <= 0:
            _fail(f"{path}.brightness", "[low, high] with 0 < low <= high <= 4", m["brightness"])
        out["brightness"] = b
    if "tilt_deg" in m:
        out["tilt_deg"] = _range(m["tilt_deg"], f"{path}.tilt_deg", 0.0, 80.0)
    return LightingSpec(**{**base.__dict__, **out})


def _drift(raw: Any, path: str, base: DriftSpec) -> DriftSpec:
    m = _mapping(raw, path, tuple(DriftSpec.__dataclass_fields__))
    out = {}
    if "rate_per_s" in m:
        out["rate_per_s"] = _rate(m, "rate_per_s", path)
    for key, bound in (("max_deg", MAX_DRIFT_DEG), ("max_mm", MAX_DRIFT_MM)):
        if key in m:
            v = _non_negative(m[key], f"{path}.{key}")
            if v > bound:
                _fail(f"{path}.{key}", f"at most {bound}", m[key])
            out[key] = v
    if "duration_s" in m:
        out["duration_s"] = _range(m["duration_s"], f"{path}.duration_s", 0.0, 600.0)
    return DriftSpec(**{**base.__dict__, **out})


#: Keys each scheduled kind accepts besides ``at`` and ``kind``.
SCHEDULE_KEYS = {
    "slip": ("arm", "angle_deg", "slide_mm"),
    "drop": ("arm",),
    "frame_lost": ("frames",),
    "dark": ("frames", "brightness"),
    "lighting": ("duration_s", "brightness", "tilt_deg", "azimuth_deg"),
    "drift": ("arm", "dq", "duration_s"),
}


def _scheduled(raw: Any, path: str) -> ScheduledFault:
    if not isinstance(raw, dict):
        _fail(path, "a mapping with at and kind", raw)
    kind = raw.get("kind")
    if kind not in SCHEDULE_KEYS:
        _fail(f"{path}.kind", "one of " + ", ".join(FAULT_KINDS), kind)
    m = _mapping(raw, path, ("at", "kind", *SCHEDULE_KEYS[kind]))
    if "at" not in m:
        raise SceneError(f"{path}.at: missing (simulated time in s)")
    at = _non_negative(m["at"], f"{path}.at")
    params: dict[str, Any] = {}
    for key, v in m.items():
        p = f"{path}.{key}"
        if key in ("at", "kind"):
            continue
        if key == "arm":
            if v not in ARMS:
                _fail(p, "psm1 or psm2", v)
            params[key] = v
        elif key == "frames":
            params[key] = _positive_int(v, p)
        elif key == "brightness":
            b = _positive(v, p)
            if kind == "dark" and b > 1:
                _fail(p, "a brightness in (0, 1]", v)
            params[key] = b
        elif key == "dq":
            dq = _vector(v, p, 3)
            for i, (x, bound) in enumerate(
                zip(dq, (MAX_DRIFT_DEG,) * 2 + (MAX_DRIFT_MM,), strict=True)
            ):
                if abs(x) > bound:
                    _fail(f"{p}[{i}]", f"|value| <= {bound} {'mm' if i == 2 else 'deg'}", x)
            params[key] = dq
        elif key in ("angle_deg", "slide_mm", "azimuth_deg"):
            params[key] = _number(v, p)
        else:  # duration_s, tilt_deg
            params[key] = _non_negative(v, p)
    if kind == "drift" and "arm" not in params:
        raise SceneError(f"{path}.arm: missing (psm1 or psm2)")
    if kind == "lighting" and "duration_s" not in params:
        raise SceneError(f"{path}.duration_s: missing (how long the lighting stays changed, s)")
    return ScheduledFault(at, kind, tuple(sorted(params.items())))


def parse_faults(raw: Any, path: str = "scene.faults") -> FaultConfig:
    """Validate a ``faults:`` value: a profile name or a mapping (see the module docstring)."""
    profiles = _profiles()
    if raw is None:
        return FaultConfig()
    if isinstance(raw, str):
        if raw not in profiles:
            _fail(path, "a profile (" + ", ".join(profiles) + ") or a mapping", raw)
        base = profiles[raw] or {}
        cfg = parse_faults({**base, "profile": "none"}, f"fault_profiles.yaml:{raw}")
        return FaultConfig(**{**cfg.__dict__, "profile": raw})
    m = _mapping(raw, path, ("profile", "servo", *FAULT_KINDS, "schedule"))
    name = m.get("profile", "none")
    if name not in profiles:
        _fail(f"{path}.profile", "one of " + ", ".join(profiles), name)
    cfg = parse_faults(name, path) if name != "none" else FaultConfig()
    out = dict(cfg.__dict__)
    if "servo" in m:
        out["servo"] = None if m["servo"] is None else _servo(m["servo"], f"{path}.servo")
    if "slip" in m:
        out["slip"] = _slip(m["slip"], f"{path}.slip", cfg.slip)
    if "drop" in m:
        out["drop"] = _drop(m["drop"], f"{path}.drop", cfg.drop)
    if "frame_lost" in m:
        out["frame_lost"] = _frames(m["frame_lost"], f"{path}.frame_lost", cfg.frame_lost, False)
    if "dark" in m:
        out["dark"] = _frames(m["dark"], f"{path}.dark", cfg.dark, True)
    if "lighting" in m:
        out["lighting"] = _lighting(m["lighting"], f"{path}.lighting", cfg.lighting)
    if "drift" in m:
        out["drift"] = _drift(m["drift"], f"{path}.drift", cfg.drift)
    if "schedule" in m:
        sched = m["schedule"]
        if not isinstance(sched, list):
            _fail(f"{path}.schedule", "a list of faults", sched)
        entries = [_scheduled(e, f"{path}.schedule[{i}]") for i, e in enumerate(sched)]
        out["schedule"] = tuple(sorted(entries, key=lambda e: e.at))
    out["profile"] = name
    return FaultConfig(**out)
