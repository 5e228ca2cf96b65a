"""Needle training/benchmark data from the simulator: stereo renders with ground-truth labels.

Front door (may import ``suture_bt.sim``; labels come from the ground-truth side of the sim:
the needle body's true pose and the renderer's segmentation). Each scene places the needle
resting on the tissue, held in either jaw, partly inserted in a port, or free in view 80-200
mm from the cameras; the arms are posed at random, often through the view (occlusion);
brightness varies up to 2× and sensor noise is added. ``variety`` may also move the phantom
and tilt the light (:mod:`scene_variety`; off for the shipped weights' data).

Dataset layout (``out/``): ``shard_XXXX.npz`` with ``images`` (n, H, W, 3) uint8 at the network
input size, ``masks`` (n, H, W) uint8 needle coverage ×255, ``keypoints`` (n, 2, 2) base/tip
pixels at that size, ``visible`` (n, 2), ``pose_cam`` (n, 4, 4) needle pose in the eye's
camera frame, ``scenario`` (n,); and ``meta.json`` (seed, sizes, timing).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from suture_bt.datagen.scene_variety import DEFAULT_SCENE, SceneVariety
from suture_bt.geometry import NeedleModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.interfaces import CameraModel, StereoCameraModel
from suture_bt.kinematics import forward_kinematics
from suture_bt.kinematics.psm import GRASP_DEPTH
from suture_bt.perception.network import INPUT_SIZE
from suture_bt.sim.camera import LIGHT_DIRECTION_WORLD
from suture_bt.transforms import invert, make_transform, rpy_to_matrix

SCENARIOS = ("resting", "held_psm1", "held_psm2", "in_port", "free")
SCENARIO_WEIGHTS = (0.2, 0.2, 0.2, 0.15, 0.25)
#: Render size for training images (one EGL tile), downsampled ×2 to the network input.
RENDER_SIZE = (960, 544)
#: Joint sampling ranges for random arm poses (rad, rad, m, rad, rad, rad).
Q_LOW = np.array([-1.2, -0.9, 0.08, -2.5, -1.3, -1.3])
Q_HIGH = np.array([1.2, 0.9, 0.22, 2.5, 1.3, 1.3])


@dataclass(frozen=True)
class SceneSample:
    """One sampled scene: needle pose (world), arm joints and jaws, image-quality knobs."""

    scenario: str
    T_world_needle: np.ndarray
    q: dict
    jaw: dict
    brightness: float
    noise_std: float
    #: Direction towards the light (world); None: the scene's overhead light.
    light_direction: tuple[float, float, float] | None = None


def _in_view(cam: CameraModel, pts_world: np.ndarray, margin: float, zr=(0.06, 0.22)) -> bool:
    pc = cam.to_camera(pts_world)
    if np.any(pc[:, 2] < zr[0]) or np.any(pc[:, 2] > zr[1]):
        return False
    uv = cam.project(pts_world)
    return bool(
        np.all(uv[:, 0] > margin * cam.width)
        and np.all(uv[:, 0] < (1 - margin) * cam.width)
        and np.all(uv[:, 1] > margin * cam.height)
        and np.all(uv[:, 1] < (1 - margin) * cam.height)
    )


def grasp_transform(model: NeedleModel, arc_angle: float, flip: bool) -> np.ndarray:
    """Needle pose in the tip frame for a jaw grasp at ``arc_angle`` (as the world's grasp)."""
    tangent = np.array([np.sin(arc_angle), -np.cos(arc_angle), 0.0])
    radial = np.array([np.cos(arc_angle), np.sin(arc_angle), 0.0])
    R = np.stack([tangent, radial, [0.0, 0.0, 1.0]])
    if flip:
        R = np.diag([1.0, -1.0, -1.0]) @ R
    return make_transform(R, np.array([0.0, 0.0, -GRASP_DEPTH]) - R @ model.point_at(arc_angle))


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


class SceneSampler:
    """Draws needle/arm configurations that put the needle in the left eye's view."""

    def __init__(
        self, stereo: StereoCameraModel, bases: dict, T_world_phantom, ports, model, buried=None
    ):
        self.buried = buried if buried is not None else (lambda pts: np.zeros(len(pts), bool))
        self.stereo = stereo
        self.bases = bases
        self.T_world_phantom = T_world_phantom
        self.ports = ports
        self.model = model
        self._ends = np.stack([model.base, model.tip, model.point_at(2.07)])
        self._line = model.centerline(12)

    def _needle_ok(self, T: np.ndarray, zr, allow_buried: bool = False) -> bool:
        pts = self._ends @ T[:3, :3].T + T[:3, 3]
        if not (
            _in_view(self.stereo.left, pts, 0.03, zr) and _in_view(self.stereo.right, pts, 0.03, zr)
        ):
            return False
        buried = self.buried(self._line @ T[:3, :3].T + T[:3, 3])
        return (
            bool(buried[:4].sum() == 0 and buried.mean() < 0.6)
            if allow_buried
            else not buried.any()
        )

    def _arm_q(self, arm: str, rng, in_view: bool, tries: int = 400) -> np.ndarray:
        """Random joints; with ``in_view`` the tip lands in the left eye's view."""
        for _ in range(tries):
            q = rng.uniform(Q_LOW, Q_HIGH)
            if not in_view:
                return q
            tip = (self.bases[arm] @ forward_kinematics(q))[:3, 3]
            if (
                _in_view(self.stereo.left, tip[None], 0.02, (0.05, 0.2))
                and not self.buried(tip[None]).any()
            ):
                return q
        return q

    def sample(self, rng: np.random.Generator, scenario: str | None = None, zr=(0.07, 0.21)):
        """A scene; ``zr`` bounds the needle's camera depth (m)."""
        if scenario is None:
            scenario = str(rng.choice(SCENARIOS, p=SCENARIO_WEIGHTS))
        q = {a: self._arm_q(a, rng, rng.random() < 0.7) for a in ("psm1", "psm2")}
        jaw = {a: float(rng.uniform(0.0, 1.0)) for a in ("psm1", "psm2")}
        T = None
        # A free needle's depth is drawn once per 100 attempts (uniform over ``zr``): re-drawing
        # it on every rejected attempt would skew the depths towards the near, easily visible
        # ones; keeping it for good would fail where nothing at that depth is above the floor.
        z_free = rng.uniform(*zr)
        for attempt in range(600):
            if attempt == 300:
                scenario = "free"
            if attempt % 100 == 99:
                z_free = rng.uniform(*zr)
            if scenario == "resting":
                x = rng.choice([-1, 1]) * rng.uniform(0.012, 0.04)
                y = rng.uniform(-0.045, 0.065)
                R = rpy_to_matrix((np.pi * rng.integers(2), 0.0, rng.uniform(-np.pi, np.pi)))
                T = self.T_world_phantom @ make_transform(
                    R, (x, y, TISSUE_TOP_Z + self.model.wire_radius)
                )
            elif scenario.startswith("held"):
                arm = scenario.split("_")[1]
                q[arm] = self._arm_q(arm, rng, True)
                jaw[arm] = 0.08
                a = rng.uniform(self.model.tip_angle + 0.3, self.model.base_angle - 0.1)
                T_tip = self.bases[arm] @ forward_kinematics(q[arm])
                T = T_tip @ grasp_transform(self.model, a, bool(rng.integers(2)))
            elif scenario == "in_port":
                port = self.ports[int(rng.integers(len(self.ports)))]
                a = rng.uniform(self.model.tip_angle + 0.25, self.model.tip_angle + 1.4)
                # Needle point at arc angle a sits at the port, its tangent pointing inwards.
                inward = -port.T[:3, 2]
                tilt = _random_rotation(rng)
                t_dir = inward + 0.5 * (tilt[:, 0] - inward * (tilt[:, 0] @ inward))
                t_dir /= np.linalg.norm(t_dir)
                side = np.cross(t_dir, tilt[:, 1])
                side /= np.linalg.norm(side)
                radial = np.cross(side, t_dir)  # completes a right-handed needle frame
                Rn = np.stack(
                    [self.model.tangent_at(a), np.array([np.cos(a), np.sin(a), 0.0]), [0, 0, 1.0]]
                )
                Rw = np.stack([t_dir, radial, side], 1)
                R = Rw @ Rn
                T = make_transform(R, port.T[:3, 3] - R @ self.model.point_at(a))
            else:
                cam = self.stereo.left
                z = z_free
                u = rng.uniform(0.15, 0.85) * cam.width
                v = rng.uniform(0.15, 0.85) * cam.height
                pc = np.array([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z])
                T = cam.T_world_cam @ make_transform(_random_rotation(rng), pc)
            if self._needle_ok(T, zr, allow_buried=scenario == "in_port"):
                break
        else:  # last resort (not reached in 1500 test draws): a needle resting beside the ridge
            scenario = "resting"
            T = self.T_world_phantom @ make_transform(
                position=(0.02, 0.01, TISSUE_TOP_Z + self.model.wire_radius)
            )
        return SceneSample(
            scenario,
            T,
            q,
            jaw,
            brightness=float(rng.uniform(0.7, 2.0)),
            noise_std=float(rng.uniform(0.0, 6.0)),
        )


class SimScene:
    """A world whose arms and needle are posed directly from :class:`SceneSample` values."""

    def __init__(self, width: int, height: int, seed: int = 0) -> None:
        from suture_bt.sim.camera import render_view, stereo_model
        from suture_bt.sim.phantom_build import BLOCK_X, BLOCK_Y
        from suture_bt.sim.scene import default_scene
        from suture_bt.sim.world import World, psm_base_frame

        self._render_view = render_view
        self._block_xy = (BLOCK_X, BLOCK_Y)
        self.world = World.from_scene(default_scene())
        if self.world.phantom is None:
            from suture_bt.sim.phantom_body import PhantomBody

            self.world.phantom = PhantomBody(self.world.client, self.world.task.phantom)
        self.stereo = stereo_model(width, height)
        bases = {a: psm_base_frame(a) for a in ("psm1", "psm2")}
        self.model = self.world.task.needle
        self.sampler = SceneSampler(
            self.stereo,
            bases,
            self.world.task.phantom.T_world_phantom,
            self.world.task.phantom.ports(),
            self.model,
            buried=self._buried,
        )

    def _buried(self, pts_world: np.ndarray) -> np.ndarray:
        """Points inside the tissue, under the block's top face (within its footprint) or
        under the cavity floor.

        Beyond the block's edges the needle may hang lower than the tissue top (far from the
        cameras, against the dark background); whatever the block hides there is hidden in the
        rendered image too. The floor is solid: a needle through it is no real scene (its cut
        at the floor looks like an end, which no image of a real needle shows).
        """
        ph = self.world.task.phantom.T_world_phantom
        q = (pts_world - ph[:3, 3]) @ ph[:3, :3]
        BLOCK_X, BLOCK_Y = self._block_xy
        footprint = (
            (BLOCK_X[0] - 0.002 <= q[:, 0])
            & (q[:, 0] <= BLOCK_X[1] + 0.002)
            & (BLOCK_Y[0] - 0.002 <= q[:, 1])
            & (q[:, 1] <= BLOCK_Y[1] + 0.002)
        )
        under = footprint & (q[:, 2] < TISSUE_TOP_Z + 0.0003)
        phantom = self.world.phantom
        return under | phantom.inside_tissue(pts_world) | phantom.below_floor(pts_world)

    def move_phantom(self, T_world_phantom: np.ndarray) -> None:
        """Rebuild the phantom (tissue, ridge, port squares and floor) at ``T_world_phantom``,
        and tell the world's known task and the sampler (benchmarks draw held-out phantom
        poses per scene; the arms and the camera stay). A SimScene steps no physics, so the
        world's crossing bookkeeping is left as it was."""
        from suture_bt.geometry import PhantomModel
        from suture_bt.sim.phantom_body import PhantomBody

        world = self.world
        world.phantom.remove()
        phantom = PhantomModel(np.asarray(T_world_phantom, float).copy())
        world.task = replace(world.task, phantom=phantom)
        world.phantom = PhantomBody(world.client, phantom, world.task.needle)
        self.sampler.T_world_phantom = phantom.T_world_phantom
        self.sampler.ports = phantom.ports()

    def apply(self, s: SceneSample) -> None:
        for a in ("psm1", "psm2"):
            self.world.arms[a].body.set_joints(s.q[a], s.jaw[a])
        self.world.needle.set_pose(s.T_world_needle)

    def render(self, eye: str, s: SceneSample, rng: np.random.Generator):
        """(rgb with brightness and noise, boolean needle mask) at the sampler's resolution."""
        cam = self.stereo.left if eye == "left" else self.stereo.right
        r = self._render_view(self.world.client, cam, True, s.light_direction)
        mask = r.mask(self.world.needle.id)
        img = r.rgb.astype(np.float32) * s.brightness
        if s.noise_std > 0:
            img += rng.normal(0.0, s.noise_std, img.shape).astype(np.float32)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8), mask

    def close(self) -> None:
        self.world.close()


def _downsample(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def _labels(cam: CameraModel, T_world_needle, model: NeedleModel, mask: np.ndarray, scale: float):
    ends = cam.project(
        np.stack([model.base, model.tip]) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
    )
    vis = []
    for u, v in ends:
        ui, vi = int(round(u)), int(round(v))
        win = mask[max(vi - 3, 0) : vi + 4, max(ui - 3, 0) : ui + 4]
        vis.append(bool(win.any()))
    return (ends + 0.5) * scale - 0.5, np.array(vis)


#: Share of scenes kept although the needle is hidden in the left image (negative examples).
HIDDEN_SHARE = 0.05
#: Fewest needle pixels (render size) for the left image to count as showing the needle.
MIN_VISIBLE_PX = 30


def _visible_scene(sim: SimScene, rng: np.random.Generator, relight=None, tries: int = 20):
    """A sampled scene whose needle shows in the left image (the sampler's geometric checks
    miss the block hiding a needle beside it), with that image: (sample, (rgb, mask)).
    A few hidden-needle scenes are kept on purpose as negatives. ``relight`` sets a sample's
    light and gain."""
    for _ in range(tries):
        s = sim.sampler.sample(rng)
        s = s if relight is None else relight(s)
        sim.apply(s)
        rgb, mask = sim.render("left", s, rng)
        if mask.sum() >= MIN_VISIBLE_PX or rng.random() < HIDDEN_SHARE:
            break
    return s, (rgb, mask)


def generate(
    n: int,
    out: Path,
    seed: int = 0,
    shard_size: int = 200,
    progress: bool = True,
    variety: SceneVariety = DEFAULT_SCENE,
) -> dict:
    """Render ``n`` stereo scenes (2n images) into ``out``, the phantom's pose and the light
    varied as ``variety`` says; return the meta data."""
    if n < 1:
        raise ValueError(f"n must be ≥ 1, got {n}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    W, H = RENDER_SIZE
    net_w, net_h = INPUT_SIZE
    scale = net_w / W
    sim = SimScene(W, H, seed)
    buf: dict[str, list] = {
        k: []
        for k in (
            *("images", "masks", "keypoints", "visible", "pose_cam", "scenario"),
            *("phantom_moved", "light"),
        )
    }
    T_default, moved = sim.world.task.phantom.T_world_phantom.copy(), False
    shard = 0

    def flush() -> None:
        nonlocal shard
        if not buf["images"]:
            return
        np.savez(out / f"shard_{shard:04d}.npz", **{k: np.stack(v) for k, v in buf.items()})
        shard += 1
        for v in buf.values():
            v.clear()

    try:
        for i in tqdm(range(n), desc="needle data", disable=not progress):
            if i % variety.phantom_block == 0:
                T_phantom = variety.phantom_pose(seed, i // variety.phantom_block, sim.stereo)
                if T_phantom is not None or moved:  # the default scene is never rebuilt
                    sim.move_phantom(T_phantom if T_phantom is not None else T_default)
                moved = T_phantom is not None
            rng = np.random.default_rng([seed, i])
            s, first = _visible_scene(sim, rng, partial(variety.light, seed=seed, scene=i))
            for eye, cam in (("left", sim.stereo.left), ("right", sim.stereo.right)):
                rgb, mask = first if eye == "left" else sim.render(eye, s, rng)
                kp, vis = _labels(cam, s.T_world_needle, sim.model, mask, scale)
                buf["images"].append(_downsample(rgb, (net_w, net_h)))
                cov = _downsample(mask.astype(np.float32), (net_w, net_h))
                buf["masks"].append(np.round(cov * 255).astype(np.uint8))
                buf["keypoints"].append(kp.astype(np.float32))
                buf["visible"].append(vis)
                buf["pose_cam"].append(invert(cam.T_world_cam) @ s.T_world_needle)
                buf["scenario"].append(SCENARIOS.index(s.scenario))
                buf["phantom_moved"].append(moved)
                buf["light"].append([*(s.light_direction or LIGHT_DIRECTION_WORLD), s.brightness])
            if len(buf["images"]) >= 2 * shard_size:
                flush()
        flush()
    finally:
        sim.close()
    meta = {
        "n_scenes": n,
        "n_images": 2 * n,
        "seed": seed,
        "render_size": [W, H],
        "input_size": [net_w, net_h],
        "scenarios": list(SCENARIOS),
        "variety": asdict(variety),
        "seconds": round(time.time() - t0, 1),
    }
    (out / "meta.json").write_text(json.dumps(meta, indent=2))
    return meta
