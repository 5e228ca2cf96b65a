"""What a campaign varies, and each trial's draw from its own seed.

A trial's scene is the base scene (the embedded SRC scene at the Task 3 start, or ``--scene``)
with these fields replaced by values drawn from ``numpy.random.default_rng([seed, stream])``,
one stream per aspect, so adding an aspect never changes the others' draws and the same seed
gives the same scene on any machine or backend:

* both arms' hidden joint offsets, uniform over the full SRC bounds (±5°, ±5°, ±5 mm);
* the needle start: in PSM2's jaw at a drawn grasp arc angle, or (with ``resting_fraction``
  > 0) resting on the tissue: at a place drawn on the flat tissue beside the ridge, face up or
  down, turned at random and inside both cameras' views (``resting_place = "view"``, the
  default), or at the SRC start pose (``"src"``, which lies below the image's bottom edge in
  this camera: no tree can find it from images);
* the phantom pose, jittered about the base scene's: ± ``phantom_xy_mm`` / ``phantom_z_mm``,
  ± ``phantom_yaw_deg`` about the vertical and ± ``tilt_deg`` of roll and pitch (defaults: a few
  mm and degrees; wider ranges stand in for held-out scenes), drawn again while a port would
  lie outside either image;
* the camera's noise and brightness (inside the perception training ranges);
* the low-level servo's bandwidth, damping, friction and load, per arm and joint, drawn by the
  world from the scene seed over the ranges of ``fault_profiles.yaml`` (``servo = "drawn"``,
  the default; ``"nominal"`` holds the SRC servo);
* the fault profile (``none``, ``mild``, ``harsh``), through the scene's ``faults:`` section.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

#: Hidden joint-offset bounds (deg, deg, mm): the full SRC range (DESIGN.md §5).
OFFSET_BOUND = (5.0, 5.0, 5.0)
ARMS = ("psm1", "psm2")
#: Independent random streams, one per aspect of a trial.
STREAMS = {"offsets": 1, "needle": 2, "phantom": 3, "camera": 4, "resting": 5}
#: The profile whose servo ranges a ``servo = "drawn"`` campaign uses under fault profile none.
SERVO_PROFILE = "mild"
#: Widest phantom jitter a campaign accepts (mm, deg): beyond it the ports leave the arms'
#: reach or the cameras' view, and trials would measure the scene, not the tree.
MAX_MOVE_MM, MAX_YAW_DEG, MAX_TILT_DEG = 50.0, 45.0, 15.0
#: Every port at least this far inside both images (px), in this many phantom draws.
PORT_MARGIN_PX, PHANTOM_TRIES = 40.0, 200


def servo_ranges(profile: str = SERVO_PROFILE) -> dict[str, list[float]]:
    """The servo ranges of a fault profile in ``fault_profiles.yaml`` (the one place where
    the recovery issue's ranges live), e.g. ``{"bandwidth_hz": [3.0, 12.0], ...}``."""
    from importlib import resources

    import yaml

    text = resources.files("suture_bt.sim").joinpath("fault_profiles.yaml").read_text()
    return dict((yaml.safe_load(text).get(profile) or {}).get("servo") or {})


@dataclass(frozen=True)
class Randomization:
    """The ranges a campaign draws from (all symmetric ranges are ± the value)."""

    grasp_arc_deg: tuple[float, float] = (145.0, 165.0)
    resting_fraction: float = 0.0
    resting_place: str = "view"  # "view": drawn on the tissue in view | "src": SRC start pose
    phantom_xy_mm: float = 3.0
    phantom_z_mm: float = 1.5
    phantom_yaw_deg: float = 3.0
    tilt_deg: float = 1.5
    noise_std: tuple[float, float] = (0.0, 3.0)
    brightness: tuple[float, float] = (0.8, 1.25)
    servo: str = "drawn"  # "drawn" (per run, arm and joint, by the world) | "nominal"

    def __post_init__(self) -> None:
        """Reject ranges a trial could not be built from."""
        lo, hi = self.grasp_arc_deg
        if not 57.0 <= lo <= hi <= 180.0:
            raise ValueError(f"grasp arc range must lie in [57, 180] deg, got {lo}..{hi}")
        if not 0.0 <= self.resting_fraction <= 1.0:
            raise ValueError(f"resting fraction must be in [0, 1], got {self.resting_fraction}")
        if not 0.0 <= self.tilt_deg <= MAX_TILT_DEG:
            raise ValueError(
                f"phantom tilt must be in [0, {MAX_TILT_DEG:g}] deg, got {self.tilt_deg}"
            )
        for name, value, bound in (
            ("phantom x/y move", self.phantom_xy_mm, MAX_MOVE_MM),
            ("phantom z move", self.phantom_z_mm, MAX_MOVE_MM),
            ("phantom yaw", self.phantom_yaw_deg, MAX_YAW_DEG),
        ):
            if not 0.0 <= value <= bound:
                raise ValueError(f"{name} must be in [0, {bound:g}], got {value}")
        lo, hi = self.brightness
        if not 0.2 <= lo <= hi <= 3.0:
            raise ValueError(f"brightness range must lie in [0.2, 3], got {lo}..{hi}")
        if self.resting_place not in ("view", "src"):
            raise ValueError(f"resting place must be view or src, got {self.resting_place!r}")
        if self.servo not in ("nominal", "drawn"):
            raise ValueError(f"servo must be nominal or drawn, got {self.servo!r}")


@dataclass(frozen=True)
class CampaignConfig:
    """Everything that decides a campaign's trials (the trial count aside)."""

    seed: int = 0
    tree: str = "multi_throw"
    scene: str | None = None
    scene_raw: dict[str, Any] = field(default_factory=dict)
    faults: str = "none"
    oracle: bool = False
    policy: str = "stop"
    max_sim_time: float = 300.0
    rerun: str = "off"  # "save": each trial keeps its rerun recording (run.rrd)
    randomization: Randomization = field(default_factory=Randomization)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (stored in ``campaign.json``)."""
        return asdict(self)

    @property
    def fingerprint(self) -> str:
        """Short hash of everything that decides the trials (the scene's content, not its
        path): a resumed campaign must match."""
        doc = {k: v for k, v in self.to_dict().items() if k != "scene"}
        text = json.dumps(doc, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def trial_seed(config: CampaignConfig, index: int) -> int:
    """Seed of trial ``index``: consecutive from the campaign seed."""
    return int(config.seed) + int(index)


def _rng(seed: int, aspect: str) -> np.random.Generator:
    """The random stream of one aspect of one trial."""
    return np.random.default_rng([seed, 18, STREAMS[aspect]])


def _r(x: float, digits: int = 4) -> float:
    """Round a draw so that it survives JSON and YAML exactly."""
    return round(float(x), digits)


def draw(config: CampaignConfig, index: int) -> dict[str, Any]:
    """Trial ``index``'s draws as scene overrides (same layout as a scene file)."""
    seed, rz = trial_seed(config, index), config.randomization
    out: dict[str, Any] = {"seed": seed}
    g = _rng(seed, "offsets")
    out["arms"] = {
        arm: {"joint_offset": [_r(v, 3) for v in g.uniform(-1.0, 1.0, 3) * OFFSET_BOUND]}
        for arm in ARMS
    }
    g = _rng(seed, "needle")
    resting = bool(g.random() < rz.resting_fraction)
    grasp = _r(g.uniform(*rz.grasp_arc_deg), 2)
    out["needle"] = (
        {"start": "in_psm2_jaw", "grasp_arc_angle_deg": grasp}
        if not resting
        else {"start": "resting"}
        if rz.resting_place == "src"
        else None  # drawn below, once the phantom pose is known
    )
    from suture_bt.campaign.resting_start import camera_of

    camera = camera_of(config.scene_raw)
    out["phantom"] = _phantom_in_view(config, _rng(seed, "phantom"), camera)
    if out["needle"] is None:
        out["needle"] = _resting_in_view(_rng(seed, "resting"), out["phantom"], camera)
    g = _rng(seed, "camera")
    out["camera"] = {
        "noise_std": _r(g.uniform(*rz.noise_std), 3),
        "brightness": _r(g.uniform(*rz.brightness), 3),
    }
    faults = _faults(config.faults, rz.servo)
    if faults is not None:
        out["faults"] = faults
    return out


def _phantom_in_view(config: CampaignConfig, g: np.random.Generator, camera: Any) -> dict[str, Any]:
    """The phantom pose jittered about the base scene's (:func:`phantom_pose_in_view`)."""
    base = config.scene_raw.get("phantom", {})
    p0 = base.get("position", [0.0, 0.0, 0.0])
    r0 = base.get("rpy", [0.0, 0.0, 0.0])
    return phantom_pose_in_view(config.randomization, g, camera, p0, r0)


def phantom_pose_in_view(
    rz: Randomization,
    g: np.random.Generator,
    camera: Any,
    p0=(0.0, 0.0, 0.0),
    r0=(0.0, 0.0, 0.0),
) -> dict[str, Any]:
    """A phantom pose (``{"position", "rpy"}``, a scene file's ``phantom:``) jittered within
    ``rz``'s ranges about the position ``p0`` and the RPY ``r0``; a draw that puts a port
    outside either image of ``camera`` (``PORT_MARGIN_PX`` to spare) is drawn again (the tree
    confirms the emerged tip from images: such a scene measures the camera's placement, not
    the tree). Within the default ranges every first draw is kept."""
    from suture_bt.campaign.resting_start import in_view
    from suture_bt.geometry import PhantomModel
    from suture_bt.transforms import pose_to_transform

    for _ in range(PHANTOM_TRIES):
        xy = g.uniform(-1.0, 1.0, 2) * rz.phantom_xy_mm * 1e-3
        z = g.uniform(-1.0, 1.0) * rz.phantom_z_mm * 1e-3
        roll, pitch = np.deg2rad(g.uniform(-1.0, 1.0, 2) * rz.tilt_deg)
        yaw = np.deg2rad(g.uniform(-1.0, 1.0) * rz.phantom_yaw_deg)
        pose = {
            "position": [_r(p0[0] + xy[0], 6), _r(p0[1] + xy[1], 6), _r(p0[2] + z, 6)],
            "rpy": [_r(r0[0] + roll, 6), _r(r0[1] + pitch, 6), _r(r0[2] + yaw, 6)],
        }
        T = pose_to_transform(pose["position"], pose["rpy"])
        ports = np.array([port.position for port in PhantomModel(T).ports()])
        if in_view(camera, ports, PORT_MARGIN_PX):
            return pose
    raise ValueError(f"no phantom pose with every port in view after {PHANTOM_TRIES} draws")


def _resting_in_view(
    g: np.random.Generator, phantom: dict[str, Any], camera: Any
) -> dict[str, Any]:
    """A resting start drawn on the tissue in both views of the trial's camera."""
    from suture_bt.campaign.resting_start import resting_in_view
    from suture_bt.transforms import pose_to_transform

    T_world_phantom = pose_to_transform(phantom["position"], phantom["rpy"])
    return resting_in_view(g, T_world_phantom, camera)


def _faults(profile: str, servo: str) -> str | dict[str, Any] | None:
    """The trial's ``faults:`` section: the profile, with the servo drawn from the ranges (the
    world draws them per arm and joint from the scene seed) or held nominal."""
    if servo == "drawn":
        if profile == "none":
            return {"profile": "none", "servo": servo_ranges()}
        return profile  # mild and harsh draw the servo from their own ranges
    return None if profile == "none" else {"profile": profile, "servo": None}


def merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """Deep merge of plain dicts (override wins)."""
    merged = dict(base)
    for k, v in override.items():
        if isinstance(v, dict) and isinstance(merged.get(k), dict):
            merged[k] = merge(merged[k], v)
        else:
            merged[k] = v
    return merged


def trial_scene_dict(config: CampaignConfig, index: int) -> dict[str, Any]:
    """The full override dict of trial ``index``: the base scene file's keys, then the draws."""
    return merge(config.scene_raw, draw(config, index))


def offset_magnitude(scene: dict[str, Any]) -> float:
    """Largest normalised joint offset of a trial's arms (|Δq_j| / bound_j, 0..1)."""
    worst = 0.0
    for arm in ARMS:
        spec = scene.get("arms", {}).get(arm, {}).get("joint_offset")
        if isinstance(spec, list | tuple):
            worst = max(worst, *(abs(v) / b for v, b in zip(spec, OFFSET_BOUND, strict=True)))
    return worst


def faults_supported() -> bool:
    """Whether the scene parser knows a ``faults:`` section (issue 16 adds it)."""
    from suture_bt.sim.scene import SceneError, scene_from_dict

    try:
        scene_from_dict({"faults": "none"})
    except SceneError:
        return False
    return True
