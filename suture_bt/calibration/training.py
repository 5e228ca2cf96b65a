"""Training of the offset regressor (and its data from projected keypoints); no simulator imports.

The regressor's data are the 3-D keypoints of the offset arm (forward kinematics of
q_meas + Δq on joints 1-3) projected through the SRC camera model, with Δq uniform within the
bounds, the measured joints jittered around the calibration pose (the servo may stop short),
and fresh Gaussian pixel noise (σ drawn per sample up to ``noise_px_max``) every epoch, so the
MLP learns the keypoint detector's noise level rather than a noiseless inverse.
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

#: Jitter of the measured joints around the calibration pose (rad, rad, m, rad, rad, rad).
MEASURED_JITTER = np.array([np.deg2rad(1.0), np.deg2rad(1.0), 0.0005] + [np.deg2rad(2.0)] * 3)


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


def noisy(pixels: np.ndarray, rng: np.random.Generator, noise_px_max: float) -> np.ndarray:
    """Pixels with Gaussian noise whose σ is drawn uniformly in [0, noise_px_max] per sample."""
    sigma = rng.uniform(0.0, noise_px_max, (pixels.shape[0], 1, 1))
    return pixels + rng.normal(size=pixels.shape) * sigma


def train_arm(
    arm: str,
    data: ProjectedSet,
    *,
    epochs: int = 60,
    batch: int = 256,
    lr: float = 1e-3,
    noise_px_max: float = 1.5,
    seed: int = 0,
    progress: bool = True,
) -> OffsetMLP:
    """Train one arm's MLP with Adam (MSE on scaled outputs, cosine learning-rate decay)."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed + 1)
    model = OffsetMLP()
    x0 = regressor_features(arm, noisy(data.pixels, rng, noise_px_max), data.q_meas)
    model.set_scaling(x0, data.offsets)
    y = model.scale_y(data.offsets)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    n = data.offsets.shape[0]
    steps = epochs * ((n + batch - 1) // batch)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    bar = tqdm(range(epochs), desc=f"offset MLP {arm}", disable=not progress)
    for _ in bar:
        x = model.scale_x(
            regressor_features(arm, noisy(data.pixels, rng, noise_px_max), data.q_meas)
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
    noise_px_max: float = 1.5,
    progress: bool = True,
) -> OffsetRegressor:
    """Train both arms' regressors on projected keypoints (seeded, reproducible)."""
    reg = new_regressor()
    for k, arm in enumerate(reg.models):
        data = projected_dataset(arm, n_per_arm, seed=seed * 100 + k)
        reg.models[arm] = train_arm(
            arm, data, epochs=epochs, noise_px_max=noise_px_max, seed=seed, progress=progress
        )
    reg.meta.update(
        {"n_per_arm": n_per_arm, "seed": seed, "epochs": epochs, "noise_px_max": noise_px_max}
    )
    return reg
