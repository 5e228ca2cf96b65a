"""Calibration training/benchmark data from the simulator: keypoint-net windows with labels.

Front door (may import ``suture_bt.sim``). Each sample puts one arm at its calibration pose
with a random hidden offset (uniform within the bounds, slightly beyond) and a random servo
shortfall, the other arm at its start or calibration pose, and renders the left eye's network
window — centred where the arm is *expected* from its measured joints, exactly as
``calibrate`` will — at the network's input size (rendered at 2× and box-averaged 2×2, as a
full-resolution capture is box-averaged 4×4). Labels come from the simulator's own body: the
pybullet link frames of the clevis and jaw blades (``PSMBody.link_pose``), projected into the
window. Pixels outside the camera's image are black, as in a real capture.

Layout (``out/``): ``calibration_XXXX.npz`` shards with ``images`` (n, 256, 256, 3) uint8,
``keypoints`` (n, 4, 2) window px, ``arm`` (n,) 0/1, ``offset`` (n, 3), ``q_meas`` (n, 6),
``window`` (n, 3) (u0, v0, scale); and ``meta.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from suture_bt.calibration.calibration_pose import (
    CALIBRATION_JAW,
    CALIBRATION_POSES,
    OFFSET_BOUND,
    expected_keypoints,
)
from suture_bt.calibration.jaw_keypoints import (
    CLEVIS_CORNERS,
    JAW_HALF_THICKNESS,
    JAW_TIP_LENGTH,
)
from suture_bt.calibration.keypoint_net import INPUT_SIZE, Window, window_around
from suture_bt.calibration.scene_geometry import ARM_NAMES
from suture_bt.calibration.training import WINDOW_JITTER
from suture_bt.interfaces import CameraModel

SHARD = 250
#: Offsets are drawn 10 % beyond the bounds so the net has seen the box's edges.
OFFSET_MARGIN = 1.1


def sim_keypoints_world(body) -> np.ndarray:
    """The 4 keypoints (4×3, world) from the simulated arm's own link frames (the labels)."""
    from suture_bt.sim.psm_body import LINK_JAWS, LINK_WRIST_PITCH

    T5 = body.link_pose(LINK_WRIST_PITCH)
    pts = list(CLEVIS_CORNERS @ T5[:3, :3].T + T5[:3, 3])
    for link, side in zip(LINK_JAWS, (-1.0, 1.0), strict=True):
        T = body.link_pose(link)
        pts.append(
            T[:3, :3] @ np.array([side * JAW_HALF_THICKNESS, JAW_TIP_LENGTH, 0.0]) + T[:3, 3]
        )
    return np.array(pts)


def render_window(client: int, cam: CameraModel, win: Window) -> np.ndarray:
    """The network window of ``cam``'s image: rendered at 2×, box-averaged, black off-image."""
    from suture_bt.sim.camera import render_view

    wcam2 = win.camera(cam).scaled(2 * INPUT_SIZE, 2 * INPUT_SIZE)
    rgb = render_view(client, wcam2, with_segmentation=False).rgb
    img = cv2.resize(rgb, (INPUT_SIZE, INPUT_SIZE), interpolation=cv2.INTER_AREA)
    # Black outside the real image (a capture has nothing there).
    uv = win.to_image(np.stack(np.meshgrid(np.arange(INPUT_SIZE), np.arange(INPUT_SIZE)), -1))
    inside = (uv[..., 0] >= -0.5) & (uv[..., 0] < cam.width - 0.5)
    inside &= (uv[..., 1] >= -0.5) & (uv[..., 1] < cam.height - 0.5)
    img[~inside] = 0
    return img


class CalibrationScenes:
    """One simulated world reused for every sample (arms posed kinematically)."""

    def __init__(self, seed: int = 0):
        from suture_bt.sim.scene import default_scene
        from suture_bt.sim.world import World

        self.world = World.from_scene(default_scene())
        self.cam = self.world.camera.model.left
        self.initial = {a: np.array(self.world.scene.arms[a].initial_jp) for a in ARM_NAMES}

    def sample(self, rng: np.random.Generator, arm: str, offset=None):
        """Pose the arms; returns (q_meas, offset, window, keypoints in image px)."""
        if offset is None:
            offset = rng.uniform(-1, 1, 3) * OFFSET_BOUND * OFFSET_MARGIN
        q_meas = CALIBRATION_POSES[arm] + rng.uniform(-1, 1, 6) * WINDOW_JITTER
        q_true = q_meas.copy()
        q_true[:3] += offset
        jaw = CALIBRATION_JAW + rng.uniform(-0.03, 0.03)
        other = ARM_NAMES[1 - ARM_NAMES.index(arm)]
        q_other = self.initial[other] if rng.random() < 0.5 else CALIBRATION_POSES[other]
        self.world.arms[other].body.set_joints(q_other, rng.uniform(0.0, 1.0))
        body = self.world.arms[arm].body
        body.set_joints(q_true, jaw)
        centre = expected_keypoints(arm, q_meas, self.cam).mean(0)
        win = window_around(centre, self.cam)
        kp = self.cam.project(sim_keypoints_world(body))
        return q_meas, np.asarray(offset), win, kp

    def close(self) -> None:
        self.world.close()


def generate(n: int, out: Path, seed: int) -> dict:
    """Render ``n`` windows (arms alternate) into ``out``; returns the meta dict."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([seed, 5])
    scenes = CalibrationScenes(seed)
    buf: dict[str, list] = {k: [] for k in ("images", "keypoints", "arm", "offset", "q_meas")}
    buf["window"] = []
    shards = 0
    t0 = time.perf_counter()

    def flush() -> None:
        nonlocal shards
        if buf["images"]:
            arrays = {k: np.array(v) for k, v in buf.items()}
            np.savez_compressed(out / f"calibration_{shards:04d}.npz", **arrays)
            shards += 1
            for v in buf.values():
                v.clear()

    try:
        for i in tqdm(range(n), desc="calibration data"):
            arm = ARM_NAMES[i % 2]
            q_meas, offset, win, kp = scenes.sample(rng, arm)
            img = render_window(scenes.world.client, scenes.cam, win)
            buf["images"].append(img)
            buf["keypoints"].append(win.to_window(kp))
            buf["arm"].append(i % 2)
            buf["offset"].append(offset)
            buf["q_meas"].append(q_meas)
            buf["window"].append((win.u0, win.v0, win.scale))
            if len(buf["images"]) == SHARD:
                flush()
        flush()
    finally:
        scenes.close()
    meta = {
        "n": n,
        "seed": seed,
        "shards": shards,
        "input_size": INPUT_SIZE,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    (out / "meta.json").write_text(json.dumps(meta, indent=1))
    return meta


def load(folder: Path) -> dict[str, np.ndarray]:
    """All shards of a dataset folder concatenated."""
    from suture_bt.calibration.training import load_windows

    return load_windows(folder)
