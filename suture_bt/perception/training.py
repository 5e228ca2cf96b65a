"""Train the needle network from a dataset folder (no simulator imports: it reads files).

Losses at the network's output stride: BCE + soft Dice on the coarse needle mask (cells the
needle covers by more than 2 %), and a penalty-reduced focal BCE on Gaussian heatmaps of both
needle ends (they look alike) and of the base (visible keypoints only). Random
crops biased towards the needle, random scale, flips and colour gain. Seeded; a tqdm bar;
validation (mask IoU, keypoint pixel error) printed at the end of every round.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from torch.nn import functional as F
from tqdm import tqdm

from suture_bt.dataset_shards import load_shards
from suture_bt.perception.network import OUTPUT_STRIDE, NeedleNet, count_parameters, save_weights

HEATMAP_SIGMA = 1.5  # output pixels
#: An output cell is "needle" when the needle covers more than this share of it.
MASK_COVERAGE = 0.02


@dataclass
class TrainConfig:
    """Hyper-parameters; ``minutes`` caps wall time, ``steps`` the number of updates."""

    steps: int = 2500
    minutes: float = 30.0
    batch: int = 16
    crop: tuple[int, int] = (192, 128)
    lr: float = 3e-3
    seed: int = 0
    width: int = 16
    val_fraction: float = 0.05
    val_every: int = 250
    threads: int = 1


def load_dataset(folders: Path | Sequence[Path]) -> dict[str, np.ndarray]:
    """All ``shard_*.npz`` of one dataset folder or several (e.g. the default scenes and the
    varied ones), concatenated in the order given; stereo pairs stay adjacent."""
    return load_shards(folders, "shard_*.npz", "suture-bt data needle")


def heatmap_targets(kp: np.ndarray, vis: np.ndarray, h: int, w: int) -> np.ndarray:
    """Gaussian heatmaps (K, h, w) at output-pixel keypoints (K, 2); zeros where not visible."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    out = np.zeros((len(kp), h, w), np.float32)
    for k, ((u, v), ok) in enumerate(zip(kp, vis, strict=True)):
        if ok:
            out[k] = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * HEATMAP_SIGMA**2))
    return out


def _to_output_px(kp: np.ndarray) -> np.ndarray:
    return (kp + 0.5) / OUTPUT_STRIDE - 0.5


class Batcher:
    """Random augmented crops (image, mask coverage, keypoints) as torch tensors."""

    def __init__(self, data: dict, idx: np.ndarray, cfg: TrainConfig, rng: np.random.Generator):
        self.d, self.idx, self.cfg, self.rng = data, idx, cfg, rng

    def sample(self, i: int, augment: bool = True):
        img, cov = self.d["images"][i], self.d["masks"][i]
        kp, vis = self.d["keypoints"][i].astype(np.float64), self.d["visible"][i].copy()
        H, W = cov.shape
        cw, ch = self.cfg.crop
        s = self.rng.uniform(0.85, 1.4) if augment else 1.0
        sw, sh = int(round(cw / s)), int(round(ch / s))
        sw, sh = min(sw, W), min(sh, H)
        ys, xs = np.nonzero(cov > 64)
        if len(xs) and self.rng.random() < 0.85:
            j = self.rng.integers(len(xs))
            cx = xs[j] + self.rng.integers(-sw // 3, sw // 3 + 1)
            cy = ys[j] + self.rng.integers(-sh // 3, sh // 3 + 1)
        else:
            cx, cy = self.rng.integers(0, W), self.rng.integers(0, H)
        x0 = int(np.clip(cx - sw // 2, 0, W - sw))
        y0 = int(np.clip(cy - sh // 2, 0, H - sh))
        im = cv2.resize(img[y0 : y0 + sh, x0 : x0 + sw], (cw, ch), interpolation=cv2.INTER_AREA)
        m = cv2.resize(
            cov[y0 : y0 + sh, x0 : x0 + sw].astype(np.float32) / 255.0,
            (cw, ch),
            interpolation=cv2.INTER_AREA,
        )
        fx, fy = cw / sw, ch / sh
        kp = np.stack([(kp[:, 0] - x0 + 0.5) * fx - 0.5, (kp[:, 1] - y0 + 0.5) * fy - 0.5], 1)
        vis &= (kp[:, 0] >= 0) & (kp[:, 0] <= cw - 1) & (kp[:, 1] >= 0) & (kp[:, 1] <= ch - 1)
        if augment and self.rng.random() < 0.5:
            im, m = im[:, ::-1], m[:, ::-1]
            kp[:, 0] = cw - 1 - kp[:, 0]
        if augment and self.rng.random() < 0.5:
            im, m = im[::-1], m[::-1]
            kp[:, 1] = ch - 1 - kp[:, 1]
        im = im.astype(np.float32) / 255.0
        if augment:
            im = np.clip(im * self.rng.uniform(0.8, 1.2) * self.rng.uniform(0.95, 1.05, 3), 0, 1)
        oh, ow = ch // OUTPUT_STRIDE, cw // OUTPUT_STRIDE
        cov_out = cv2.resize(np.ascontiguousarray(m), (ow, oh), interpolation=cv2.INTER_AREA)
        m_out = (cov_out > MASK_COVERAGE).astype(np.float32)
        bt = heatmap_targets(_to_output_px(kp), vis, oh, ow)
        heat = np.stack([bt.max(0), bt[0]])  # both ends (they look alike), and the base
        im = np.ascontiguousarray(im.transpose(2, 0, 1), dtype=np.float32)
        return im, m_out.astype(np.float32), heat, kp, vis

    def batch(self, n: int):
        items = [self.sample(int(i)) for i in self.rng.choice(self.idx, n)]
        x = torch.from_numpy(np.stack([it[0] for it in items]))
        m = torch.from_numpy(np.stack([it[1] for it in items]))[:, None]
        h = torch.from_numpy(np.stack([it[2] for it in items]))
        return x, m, h


def losses(out: torch.Tensor, m: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, dict]:
    """Mask BCE + Dice and focal heatmap loss; returns (total, parts)."""
    ml = out[:, :1]
    bce = F.binary_cross_entropy_with_logits(ml, m, pos_weight=torch.tensor(5.0))
    p = torch.sigmoid(ml)
    dice = 1 - (2 * (p * m).sum((1, 2, 3)) + 1) / (p.sum((1, 2, 3)) + m.sum((1, 2, 3)) + 1)
    hl = out[:, 1:]
    ph = torch.sigmoid(hl).clamp(1e-4, 1 - 1e-4)
    pos = h > 0.9
    focal_pos = -((1 - ph) ** 2) * torch.log(ph) * pos
    focal_neg = -((1 - h) ** 4) * ph**2 * torch.log(1 - ph) * (~pos)
    npos = pos.sum().clamp(min=1)
    heat = (focal_pos.sum() + focal_neg.sum()) / npos
    total = bce + dice.mean() + 0.5 * heat
    parts = {"bce": bce.item(), "dice": dice.mean().item(), "heat": heat.item()}
    return total, parts


@torch.inference_mode()
def evaluate(net: NeedleNet, data: dict, idx: np.ndarray) -> dict:
    """Mask IoU (coverage > 0.5) and base/tip error (input px) over whole validation images."""
    from suture_bt.perception.network import decode_ends

    net.eval()
    inter = union = 0.0
    errs = []
    for s in range(0, len(idx), 16):
        ii = idx[s : s + 16]
        x = torch.from_numpy(data["images"][ii]).permute(0, 3, 1, 2).float() / 255.0
        out = net(x)
        pm = (torch.sigmoid(out[:, 0]) > 0.5).numpy()
        H, W = data["masks"].shape[1:]
        size = (W // OUTPUT_STRIDE, H // OUTPUT_STRIDE)
        gm = [
            cv2.resize(
                data["masks"][i].astype(np.float32) / 255, size, interpolation=cv2.INTER_AREA
            )
            for i in ii
        ]
        gm = np.stack(gm) > MASK_COVERAGE
        inter += float((pm & gm).sum())
        union += float((pm | gm).sum())
        kp, _ = decode_ends(out[:, 1], out[:, 2])
        kp_in = (kp + 0.5) * OUTPUT_STRIDE - 0.5
        gt = data["keypoints"][ii]
        vis = data["visible"][ii]
        # Ends are matched to the labels in whichever order fits (base/tip look alike).
        e = np.minimum(
            np.linalg.norm(kp_in - gt, axis=-1), np.linalg.norm(kp_in[:, ::-1] - gt, axis=-1)
        )
        errs.extend(e[vis].tolist())
    net.train()
    errs = np.array(errs) if errs else np.array([np.nan])
    return {
        "mask_iou": inter / max(union, 1.0),
        "kp_err_median_px": float(np.median(errs)),
        "kp_within_3px": float(np.mean(errs < 3.0)),
    }


def train(
    data_dir: Path | Sequence[Path], out_path: Path, cfg: TrainConfig, progress: bool = True
) -> dict:
    """Train from scratch on one dataset folder or several and write the weights; return the
    final metrics and timing."""
    t0 = time.time()
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    rng = np.random.default_rng(cfg.seed)
    data = load_dataset(data_dir)
    n = len(data["images"])
    # Split by scene (images come in left/right pairs) so no scene is in both sets.
    scenes = rng.permutation(n // 2)
    n_val = max(1, int(round(cfg.val_fraction * len(scenes))))
    val = np.sort(np.concatenate([2 * scenes[:n_val], 2 * scenes[:n_val] + 1]))
    tr = np.sort(np.concatenate([2 * scenes[n_val:], 2 * scenes[n_val:] + 1]))
    net = NeedleNet(cfg.width)
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=1e-4)
    batcher = Batcher(data, tr, cfg, rng)
    history = []
    bar = tqdm(range(cfg.steps), desc="train needle", disable=not progress)
    step = 0
    for step in bar:
        x, m, h = batcher.batch(cfg.batch)
        loss, parts = losses(net(x), m, h)
        opt.zero_grad()
        loss.backward()
        opt.step()
        # Progress is whichever cap comes first (steps or wall time): warm-up, then cosine.
        prog = max((step + 1) / cfg.steps, (time.time() - t0) / (60 * cfg.minutes))
        lr = cfg.lr * min(1.0, prog / 0.03) * 0.5 * (1 + np.cos(np.pi * min(prog, 1.0)))
        for g in opt.param_groups:
            g["lr"] = max(lr, 1e-3 * cfg.lr)
        bar.set_postfix(loss=f"{loss.item():.3f}", **{k: f"{v:.3f}" for k, v in parts.items()})
        last = step == cfg.steps - 1 or prog >= 1.0
        if (step + 1) % cfg.val_every == 0 or last:
            metrics = evaluate(net, data, val)
            metrics["step"] = step + 1
            history.append(metrics)
            shown = {k: round(v, 4) for k, v in metrics.items()}
            tqdm.write(f"step {step + 1}: " + json.dumps(shown))
        if last:
            break
    net.eval()
    result = {
        "steps": step + 1,
        "seconds": round(time.time() - t0, 1),
        "parameters": count_parameters(net),
        "train_images": int(len(tr)),
        "val_images": int(len(val)),
        "config": asdict(cfg),
        "final": history[-1] if history else {},
    }
    save_weights(net, out_path, meta=result)
    return result
