"""Training of the offset regressor (and its data from projected keypoints); no simulator imports.

The regressor's data are the 3-D keypoints of the offset arm (forward kinematics of
q_meas + Δq on joints 1-3) projected through the SRC camera model, with Δq uniform within the
bounds, the measured joints jittered around the calibration pose (the servo may stop short),
and fresh Gaussian pixel noise every epoch (per keypoint, the detector's typical error
``KEYPOINT_SIGMA_PX`` times a factor drawn per sample up to ``noise_scale_max``), so the MLP
learns to weigh the keypoints as their detection deserves rather than a noiseless inverse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from suture_bt.calibration.calibration_pose import (
    CALIBRATION_JAW,
    CALIBRATION_POSES,
    OFFSET_BOUND,
)
from suture_bt.calibration.jaw_keypoints import project_keypoints
from suture_bt.calibration.offset_regressor import (
    OffsetMLP,
    OffsetRegressor,
    new_regressor,
    regressor_features,
)
from suture_bt.calibration.scene_geometry import PSM_BASES, REFERENCE_SIZE, endoscope_model
from suture_bt.dataset_shards import load_shards

#: Jitter of the measured joints around the calibration pose (rad, rad, m, rad, rad, rad) in
#: the regressor's data: the low-level servo alone stops 1.1-2.0° / 0.06-0.15 mm short
#: (DESIGN.md §5), so calibration works with or without the PI loop.
MEASURED_JITTER = np.array([np.deg2rad(2.5)] * 2 + [0.0005] + [np.deg2rad(2.5)] * 3)
#: The (narrower) jitter used for the rendered keypoint windows; the CNN does not need more.
WINDOW_JITTER = np.array([np.deg2rad(1.0), np.deg2rad(1.0), 0.0005] + [np.deg2rad(2.0)] * 3)


@dataclass(frozen=True)
class ProjectedSet:
    """Clean keypoint pixels (N×4×2, reference resolution), measured joints and offsets."""

    pixels: np.ndarray
    q_meas: np.ndarray
    offsets: np.ndarray


def projected_dataset(arm: str, n: int, seed: int) -> ProjectedSet:
    """``n`` configurations of ``arm`` at its calibration pose with random offsets."""
    if n <= 0:
        raise ValueError(f"need a positive number of samples, got {n}")
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-1.0, 1.0, (n, 3)) * OFFSET_BOUND
    q_meas = CALIBRATION_POSES[arm] + rng.uniform(-1.0, 1.0, (n, 6)) * MEASURED_JITTER
    q_actual = q_meas.copy()
    q_actual[:, :3] += offsets
    cam = endoscope_model(*REFERENCE_SIZE).left
    pixels = project_keypoints(q_actual, CALIBRATION_JAW, PSM_BASES[arm], cam)
    return ProjectedSet(pixels, q_meas, offsets)


def noisy(pixels: np.ndarray, rng: np.random.Generator, noise_scale_max: float) -> np.ndarray:
    """Pixels with Gaussian noise: per keypoint the detector's typical error
    (``KEYPOINT_SIGMA_PX``) times a factor drawn uniformly in [0, noise_scale_max] per sample."""
    from suture_bt.calibration.keypoint_net import KEYPOINT_SIGMA_PX

    scale = rng.uniform(0.0, noise_scale_max, (pixels.shape[0], 1, 1))
    sigma = np.asarray(KEYPOINT_SIGMA_PX)[None, :, None] * scale
    return pixels + rng.normal(size=pixels.shape) * sigma


def train_arm(
    arm: str,
    data: ProjectedSet,
    *,
    epochs: int = 60,
    batch: int = 256,
    lr: float = 1e-3,
    noise_scale_max: float = 1.5,
    seed: int = 0,
    progress: bool = True,
) -> OffsetMLP:
    """Train one arm's MLP with Adam (MSE on scaled outputs, cosine learning-rate decay)."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed + 1)
    model = OffsetMLP()
    x0 = regressor_features(arm, noisy(data.pixels, rng, noise_scale_max), data.q_meas)
    model.set_scaling(x0, data.offsets)
    y = model.scale_y(data.offsets)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    n = data.offsets.shape[0]
    steps = epochs * ((n + batch - 1) // batch)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    bar = tqdm(range(epochs), desc=f"offset MLP {arm}", disable=not progress)
    for _ in bar:
        x = model.scale_x(
            regressor_features(arm, noisy(data.pixels, rng, noise_scale_max), data.q_meas)
        )
        perm = torch.randperm(n)
        total = 0.0
        for i in range(0, n, batch):
            idx = perm[i : i + batch]
            loss = torch.mean((model(x[idx]) - y[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
        bar.set_postfix(mse=f"{total / n:.2e}")
    model.eval()
    return model


def train_regressor(
    n_per_arm: int = 20000,
    *,
    seed: int = 0,
    epochs: int = 60,
    noise_scale_max: float = 1.5,
    progress: bool = True,
) -> OffsetRegressor:
    """Train both arms' regressors on projected keypoints (seeded, reproducible)."""
    reg = new_regressor()
    for k, arm in enumerate(reg.models):
        data = projected_dataset(arm, n_per_arm, seed=seed * 100 + k)
        reg.models[arm] = train_arm(
            arm, data, epochs=epochs, noise_scale_max=noise_scale_max, seed=seed, progress=progress
        )
    reg.meta.update(
        {"n_per_arm": n_per_arm, "seed": seed, "epochs": epochs, "noise_scale_max": noise_scale_max}
    )
    return reg


# --------------------------------------------------------------------------- keypoint CNN


def augment_images(images: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Brightness ×[0.5, 2] (clipped, as the camera does) and Gaussian noise σ ∈ [0, 4] levels.

    Noise comes from a fixed bank of standard-normal images, rolled by a random amount per
    sample (drawing 3 M normals per batch would cost more than the networks).
    """
    n, h, w, c = images.shape
    bank = _noise_bank(h, w, c)
    x = images.astype(np.float32)
    b = rng.uniform(0.5, 2.0, n).astype(np.float32)
    s = rng.uniform(0.0, 4.0, n).astype(np.float32)
    for i in range(n):
        noise = np.roll(bank[rng.integers(len(bank))], tuple(rng.integers(0, [h, w])), (0, 1))
        x[i] = x[i] * b[i] + noise * s[i]
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


_NOISE: dict = {}


def _noise_bank(h: int, w: int, c: int) -> np.ndarray:
    """8 fixed standard-normal images (seeded) of the given size."""
    key = (h, w, c)
    if key not in _NOISE:
        _NOISE[key] = np.random.default_rng(12345).standard_normal((8, h, w, c), dtype=np.float32)
    return _NOISE[key]


def _shift(images: np.ndarray, du: int, dv: int) -> np.ndarray:
    """Images translated by integer (du, dv) pixels, zero-filled."""
    out = np.zeros_like(images)
    h, w = images.shape[1:3]
    src = images[:, max(-dv, 0) : h - max(dv, 0), max(-du, 0) : w - max(du, 0)]
    out[:, max(dv, 0) : max(dv, 0) + src.shape[1], max(du, 0) : max(du, 0) + src.shape[2]] = src
    return out


def heatmap_ce(logits: torch.Tensor, uv: torch.Tensor, sigma: float) -> torch.Tensor:
    """Cross-entropy between the spatial softmax of logits (B×K×H×W) and a Gaussian at uv."""
    b, k, h, w = logits.shape
    vv, uu = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    d2 = (uu[None, None] - uv[..., 0, None, None]) ** 2 + (
        vv[None, None] - uv[..., 1, None, None]
    ) ** 2
    target = torch.softmax((-d2 / (2 * sigma**2)).reshape(b, k, -1), -1)
    logp = torch.log_softmax(logits.reshape(b, k, -1), -1)
    return -(target * logp).sum(-1).mean()


def train_keypoint_detector(
    data: dict,
    *,
    epochs: int = 8,
    max_steps: int | None = None,
    batch: int = 16,
    lr: float = 2e-3,
    seed: int = 0,
    minutes: float | None = None,
    progress: bool = True,
):
    """Train both stages on rendered windows (``images`` N×256×256×3, ``keypoints`` N×4×2)."""
    import time

    from suture_bt.calibration.keypoint_net import (
        COARSE_POOL,
        COARSE_WIDTH,
        FINE_WIDTH,
        PATCH,
        FineNet,
        KeypointDetector,
        KeypointNet,
        box_average,
        cut_patches,
        to_input,
        window_to_coarse,
    )

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed + 7)
    images, kps = data["images"], data["keypoints"].astype(np.float64)
    n = images.shape[0]
    coarse, fine = KeypointNet(COARSE_WIDTH), FineNet(FINE_WIDTH)
    params = list(coarse.parameters()) + list(fine.parameters())
    opt = torch.optim.Adam(params, lr=lr)
    steps = epochs * ((n + batch - 1) // batch)
    if max_steps is not None:
        steps = min(steps, max_steps)
    t0 = time.perf_counter()
    step = 0
    bar = tqdm(total=steps, desc="keypoint CNN", disable=not progress)
    coarse.train()
    fine.train()
    done = False
    for _ in range(epochs):
        perm = rng.permutation(n)
        for i in range(0, n, batch):
            idx = perm[i : i + batch]
            du, dv = (int(v) for v in rng.integers(-16, 17, 2))
            imgs = augment_images(_shift(images[idx], du, dv), rng)
            uv = kps[idx] + (du, dv)
            c_uv = torch.as_tensor(window_to_coarse(uv))
            loss_c = heatmap_ce(coarse(to_input(box_average(imgs, COARSE_POOL))), c_uv, 1.0)
            # Fine stage: patches around 2 random keypoints per image, offset as a coarse
            # estimate would be.
            which = np.stack([rng.choice(4, 2, replace=False) for _ in idx])
            sel = uv[np.arange(len(idx))[:, None], which]  # B×2×2
            origins = np.floor(sel + rng.uniform(-5, 5, sel.shape) + 1 - PATCH / 2).astype(int)
            patches = np.concatenate([cut_patches(imgs[j], origins[j]) for j in range(len(idx))])
            f_uv = torch.as_tensor((sel - origins).reshape(-1, 1, 2))
            logits = fine(to_input(patches))
            own = logits[torch.arange(logits.shape[0]), torch.as_tensor(which.reshape(-1))]
            loss_f = heatmap_ce(own[:, None], f_uv, 1.0)
            loss = loss_c + loss_f
            # Cosine decay over the steps or the wall time, whichever runs out first; warm-up.
            frac = step / steps
            if minutes is not None:
                frac = max(frac, (time.perf_counter() - t0) / (60 * minutes))
            warm = min(1.0, 20 * frac + 0.05)
            for g in opt.param_groups:
                g["lr"] = lr * warm * 0.5 * (1 + np.cos(np.pi * min(frac, 1.0)))
            opt.zero_grad()
            loss.backward()
            opt.step()
            step += 1
            bar.update(1)
            bar.set_postfix(
                coarse=f"{float(loss_c.detach()):.2f}", fine=f"{float(loss_f.detach()):.2f}"
            )
            if step >= steps or (minutes is not None and time.perf_counter() - t0 > 60 * minutes):
                done = True
                break
        if done:
            break
    bar.close()
    meta = {"coarse_width": COARSE_WIDTH, "fine_width": FINE_WIDTH, "n_images": int(n)}
    meta |= {"seed": seed, "epochs": epochs, "steps": step}
    meta["seconds"] = round(time.perf_counter() - t0, 1)
    return KeypointDetector(coarse.eval(), fine.eval(), meta)


def train_calibration(
    data_dir,
    out_dir=None,
    *,
    seed: int = 0,
    steps: int | None = None,
    minutes: float | None = None,
    progress: bool = True,
) -> dict:
    """``suture-bt train calibration``: the offset MLP (projected keypoints, 20k per arm) and
    the keypoint CNN (rendered windows in ``data_dir``); both saved into ``out_dir``
    (default: the packaged weights folder)."""
    from pathlib import Path

    from suture_bt.calibration.keypoint_net import WEIGHTS_PATH as KP_PATH
    from suture_bt.calibration.offset_regressor import WEIGHTS_PATH as REG_PATH

    folder = Path(out_dir) if out_dir else REG_PATH.parent
    # The dataset first: a wrong folder is an error before anything is trained or written
    # (it used to overwrite the packaged regressor and then fail).
    data = load_windows(data_dir)
    # One thread: with the CPU shared, two intra-op threads ran 10-30× slower (measured).
    torch.set_num_threads(1)
    reg = train_regressor(20000, seed=seed, epochs=60, progress=progress)
    reg.save(folder / REG_PATH.name)
    n_val = min(VALIDATION_WINDOWS, data["images"].shape[0] // 5)
    train = {k: v[: len(v) - n_val] for k, v in data.items()}
    det = train_keypoint_detector(
        train, epochs=30, max_steps=steps, seed=seed, minutes=minutes, progress=progress
    )
    det.meta["validation_px"] = validation_error(
        det, {k: v[len(v) - n_val :] for k, v in data.items()}
    )
    det.save(folder / KP_PATH.name)
    return {"regressor": str(folder / REG_PATH.name), "detector": str(folder / KP_PATH.name)} | {
        "detector_meta": det.meta
    }


#: Windows held out (the last ones of the dataset) to report the detector's pixel error.
VALIDATION_WINDOWS = 200


def validation_error(det, data: dict) -> dict:
    """Keypoint error of the detector on held-out windows, in 1920×1080 pixels."""
    if data["images"].shape[0] == 0:
        return {}
    kp, _ = det.detect_in_windows(data["images"])
    err = np.linalg.norm(kp - data["keypoints"], axis=-1) / data["window"][:, 2:3]
    return {
        "mean": np.round(err.mean(0), 3).tolist(),
        "median": np.round(np.median(err, 0), 3).tolist(),
        "p95": np.round(np.percentile(err, 95, 0), 3).tolist(),
    }


def load_windows(folder) -> dict:
    """All ``calibration_*.npz`` shards of a dataset folder, concatenated."""
    return load_shards(folder, "calibration_*.npz", "suture-bt data calibration")
