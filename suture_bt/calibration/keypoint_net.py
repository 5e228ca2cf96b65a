"""Jaw keypoint CNN: 4 heatmaps (wrist pitch, wrist yaw, two jaw tips) on a window of the image.

Why a window: at the calibration pose the arm's expected image position is known from its
measured joints, up to the offset (±250 px at 1920×1080); a 1024-px window around it, seen at
a quarter of the SRC resolution (256×256 input), always holds the wrist and keeps the network
small and fast on a CPU. Output heatmaps have the input's resolution; keypoints are decoded
with sub-pixel precision by a soft-argmax in a small window around the peak, and the peak
value is the keypoint's confidence (low when the jaw is not in view).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import nn

from suture_bt.calibration.jaw_keypoints import NUM_KEYPOINTS
from suture_bt.interfaces import CameraModel
from suture_bt.weights_file import WeightsError, load_state, load_weights_file, save_weights_file

#: Network input side (px) and the image scale it sees relative to the SRC 1920×1080 camera.
INPUT_SIZE = 256
NET_SCALE = 0.25
REFERENCE_FX = 1080 / (2 * np.tan(0.6))
#: Soft-argmax window half-size (heatmap cells) around the peak.
DECODE_RADIUS = 3
#: Typical keypoint error of the shipped detector (1920×1080 px; validation mean 0.77, 0.67,
#: 0.48, 0.49 for clevis corner a, b, jaw tip a, b; these values ≈ the RMS). The regressor is
#: trained with noise of this size per keypoint and calibrate() normalises its residual by it.
KEYPOINT_SIGMA_PX = (1.0, 0.9, 0.6, 0.6)
#: Channel widths of the coarse and fine networks.
COARSE_WIDTH = 8
FINE_WIDTH = 12
WEIGHTS_PATH = Path(__file__).resolve().parent / "weights" / "keypoint_net.pt"
WEIGHTS_FORMAT = "suture_bt.keypoint_net.v1"
WEIGHTS_HINT = "run `suture-bt train calibration` to produce it (see README)"


def _conv(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True)
    )


class KeypointNet(nn.Module):
    """Coarse stage, a small U-Net: a stride-2 stem, 3 more stride-2 stages, back up with skips
    to half the input resolution; 4 heatmap logits (B×4×H/2×W/2)."""

    def __init__(self, width: int = COARSE_WIDTH):
        super().__init__()
        w = width
        self.stem = nn.Sequential(_conv(3, w, 2), _conv(w, w))
        self.down1 = nn.Sequential(_conv(w, 2 * w, 2), _conv(2 * w, 2 * w))
        self.down2 = nn.Sequential(_conv(2 * w, 4 * w, 2), _conv(4 * w, 4 * w))
        self.down3 = nn.Sequential(_conv(4 * w, 4 * w, 2), _conv(4 * w, 4 * w))
        self.up2 = _conv(8 * w, 4 * w)
        self.up1 = _conv(6 * w, 2 * w)
        self.up0 = nn.Sequential(_conv(3 * w, w), _conv(w, w))
        self.head = nn.Conv2d(w, NUM_KEYPOINTS, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Images (B×3×H×W, normalised; H, W multiples of 16) → heatmap logits at H/2×W/2."""
        s0 = self.stem(x)
        s1 = self.down1(s0)
        s2 = self.down2(s1)
        s3 = self.down3(s2)
        up = nn.functional.interpolate
        y = self.up2(torch.cat([up(s3, scale_factor=2.0), s2], 1))
        y = self.up1(torch.cat([up(y, scale_factor=2.0), s1], 1))
        y = self.up0(torch.cat([up(y, scale_factor=2.0), s0], 1))
        return self.head(y)


class FineNet(nn.Module):
    """Fine stage: a full-resolution heatmap (4 logits) on a small patch around one keypoint."""

    def __init__(self, width: int = FINE_WIDTH):
        super().__init__()
        w = width
        self.enc = nn.Sequential(_conv(3, w), _conv(w, w))
        self.mid = nn.Sequential(_conv(w, 2 * w, 2), _conv(2 * w, 2 * w), _conv(2 * w, 2 * w))
        self.dec = nn.Sequential(_conv(3 * w, w), _conv(w, w))
        self.head = nn.Conv2d(w, NUM_KEYPOINTS, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        e = self.enc(x)
        m = nn.functional.interpolate(self.mid(e), scale_factor=2.0)
        return self.head(self.dec(torch.cat([m, e], 1)))


#: Coarse input: the window box-averaged by this factor; heatmap cells per coarse input px.
COARSE_POOL = 4
COARSE_STRIDE = 2
#: Fine patch side (window px).
PATCH = 32


def coarse_to_window(uv: np.ndarray) -> np.ndarray:
    """Coarse heatmap-cell coordinates → window pixel coordinates (pixel-centre convention)."""
    k = COARSE_POOL * COARSE_STRIDE
    return (np.asarray(uv) + 0.5) * k - 0.5


def window_to_coarse(uv):
    """Window pixel coordinates → coarse heatmap-cell coordinates."""
    k = COARSE_POOL * COARSE_STRIDE
    return (uv + 0.5) / k - 0.5


def box_average(images: np.ndarray, k: int) -> np.ndarray:
    """k×k box average of uint8 images (…×H×W×3), H and W multiples of k."""
    *lead, h, w, c = images.shape
    x = images.reshape(*lead, h // k, k, w // k, k, c).astype(np.float32).mean(axis=(-4, -2))
    return np.rint(x).astype(np.uint8)


def patch_origin(uv) -> np.ndarray:
    """Integer top-left (window px) of the PATCH×PATCH patch centred on a point."""
    return np.floor(np.asarray(uv) + 0.5 - PATCH / 2 + 0.5).astype(int)


def cut_patches(window: np.ndarray, origins: np.ndarray) -> np.ndarray:
    """PATCH² patches (K×PATCH×PATCH×3) of a window at integer origins (K×2, (u, v)), 0-padded."""
    pad = np.pad(window, ((PATCH, PATCH), (PATCH, PATCH), (0, 0)))
    out = []
    for u, v in np.asarray(origins, dtype=int):
        u = int(np.clip(u, -PATCH, window.shape[1]))
        v = int(np.clip(v, -PATCH, window.shape[0]))
        out.append(pad[v + PATCH : v + 2 * PATCH, u + PATCH : u + 2 * PATCH])
    return np.array(out)


def to_input(images: np.ndarray) -> torch.Tensor:
    """uint8 RGB (B×H×W×3 or H×W×3) → float tensor B×3×H×W, per-image standardised.

    Per-image standardisation makes the net indifferent to global brightness (up to 2×).
    """
    x = torch.as_tensor(np.asarray(images)).float()
    if x.ndim == 3:
        x = x[None]
    x = x.permute(0, 3, 1, 2) / 255.0
    mean = x.mean(dim=(1, 2, 3), keepdim=True)
    std = x.std(dim=(1, 2, 3), keepdim=True).clamp_min(1e-3)
    return (x - mean) / std


def soft_argmax(heat: torch.Tensor, radius: int = DECODE_RADIUS) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel peaks (B×K×2, (u, v) in heatmap px) and peak probabilities (B×K) from logits.

    Softmax over the whole map, then the probability-weighted mean in a (2r+1)² window around
    the arg-max (robust to a second, distant blob).
    """
    b, k, h, w = heat.shape
    prob = torch.softmax(heat.reshape(b, k, -1).double(), -1).reshape(b, k, h, w)
    flat = prob.reshape(b, k, -1).argmax(-1)
    pv, pu = (flat // w).numpy(), (flat % w).numpy()
    p = prob.numpy()
    out = np.zeros((b, k, 2))
    peak = np.zeros((b, k))
    for i in range(b):
        for j in range(k):
            r0, r1 = max(pv[i, j] - radius, 0), min(pv[i, j] + radius + 1, h)
            c0, c1 = max(pu[i, j] - radius, 0), min(pu[i, j] + radius + 1, w)
            win = p[i, j, r0:r1, c0:c1]
            s = win.sum()
            vv, uu = np.mgrid[r0:r1, c0:c1]
            out[i, j] = ((uu * win).sum() / s, (vv * win).sum() / s)
            peak[i, j] = s
    return out, peak


@dataclass(frozen=True)
class Window:
    """Where the network input sits: a square window of the image, resampled to INPUT_SIZE."""

    u0: float  # left edge of the window, in image pixel-edge coordinates (pixel i spans [i, i+1])
    v0: float  # top edge, likewise
    scale: float  # input px per image px

    def to_image(self, uv: np.ndarray) -> np.ndarray:
        """Input-window pixel coordinates → image pixel coordinates."""
        uv = np.asarray(uv, dtype=float)
        origin = np.array([self.u0, self.v0])
        return origin + (uv + 0.5) / self.scale - 0.5

    def to_window(self, uv: np.ndarray) -> np.ndarray:
        """Image pixel coordinates → input-window pixel coordinates."""
        uv = np.asarray(uv, dtype=float)
        return np.stack(
            [
                (uv[..., 0] + 0.5 - self.u0) * self.scale - 0.5,
                (uv[..., 1] + 0.5 - self.v0) * self.scale - 0.5,
            ],
            -1,
        )

    def camera(self, cam: CameraModel) -> CameraModel:
        """The pinhole that renders exactly this window at INPUT_SIZE (for data generation)."""
        s = self.scale
        return CameraModel(
            INPUT_SIZE,
            INPUT_SIZE,
            cam.fx * s,
            cam.fy * s,
            (cam.cx + 0.5 - self.u0) * s - 0.5,
            (cam.cy + 0.5 - self.v0) * s - 0.5,
            cam.T_world_cam,
        )


def window_around(centre_uv, cam: CameraModel) -> Window:
    """The input window centred (to the nearest pixel edge) on an image point."""
    scale = NET_SCALE * REFERENCE_FX / cam.fx
    side = INPUT_SIZE / scale
    u0 = float(np.round(centre_uv[0] + 0.5 - side / 2))
    v0 = float(np.round(centre_uv[1] + 0.5 - side / 2))
    return Window(u0, v0, scale)


def extract_window(image: np.ndarray, win: Window) -> np.ndarray:
    """The window of an H×W×3 image resampled to INPUT_SIZE² (zeros outside the image)."""
    k = 1 / win.scale
    if abs(k - round(k)) < 1e-9 and float(win.u0).is_integer() and float(win.v0).is_integer():
        return _area_window(image, win, int(round(k)))
    s = win.scale  # general case: the same pixel-centre mapping as Window.to_window
    M = np.array([[s, 0.0, (0.5 - win.u0) * s - 0.5], [0.0, s, (0.5 - win.v0) * s - 0.5]])
    return cv2.warpAffine(image, M, (INPUT_SIZE, INPUT_SIZE), flags=cv2.INTER_AREA, borderValue=0)


def _area_window(image: np.ndarray, win: Window, k: int) -> np.ndarray:
    """Exact k×k box averaging of an integer-aligned window (the common case)."""
    side = INPUT_SIZE * k
    u0, v0 = int(win.u0), int(win.v0)
    h, w = image.shape[:2]
    pad = np.zeros((side, side, 3), np.float32)
    a0, a1 = max(v0, 0), min(v0 + side, h)
    b0, b1 = max(u0, 0), min(u0 + side, w)
    if a1 > a0 and b1 > b0:
        pad[a0 - v0 : a1 - v0, b0 - u0 : b1 - u0] = image[a0:a1, b0:b1]
    out = pad.reshape(INPUT_SIZE, k, INPUT_SIZE, k, 3).mean(axis=(1, 3))
    return np.rint(out).astype(np.uint8)


@dataclass
class KeypointDetector:
    """Both stages plus decoding: image + expected centre → 4 keypoints and confidences."""

    coarse: KeypointNet
    fine: FineNet
    meta: dict

    @torch.no_grad()
    def detect_in_windows(self, windows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keypoints (B×4×2, window px) and confidences (B×4, fine-stage peak mass) for B
        uint8 windows (INPUT_SIZE²)."""
        self.coarse.eval()
        self.fine.eval()
        # One intra-op thread: these nets are tiny, and on a shared 2-core CPU two OpenMP
        # threads made detection ~60× slower (465 ms vs 7 ms per window, measured).
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return self._detect(np.asarray(windows))
        finally:
            torch.set_num_threads(threads)

    def _detect(self, windows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        heat = self.coarse(to_input(box_average(windows, COARSE_POOL)))
        coarse, _ = soft_argmax(heat)
        coarse = coarse_to_window(coarse)
        b = windows.shape[0]
        origins = patch_origin(coarse)  # B×4×2
        patches = np.concatenate([cut_patches(windows[i], origins[i]) for i in range(b)])
        fheat = self.fine(to_input(patches))  # (B·4)×4×P×P
        k = np.tile(np.arange(NUM_KEYPOINTS), b)
        own = fheat[torch.arange(b * NUM_KEYPOINTS), torch.as_tensor(k)][:, None]
        fine, conf = soft_argmax(own)
        kp = origins.reshape(-1, 2) + fine[:, 0]
        return kp.reshape(b, NUM_KEYPOINTS, 2), conf.reshape(b, NUM_KEYPOINTS)

    def detect(self, image: np.ndarray, cam: CameraModel, centre_uv) -> tuple:
        """Keypoints (4×2, image px), confidences (4,) and the window used."""
        win = window_around(centre_uv, cam)
        kp, conf = self.detect_in_windows(extract_window(image, win)[None])
        return win.to_image(kp[0]), conf[0], win

    def save(self, path: Path = WEIGHTS_PATH) -> None:
        """Write both stages' weights and the (plain-typed) meta as a data-only file."""
        state = {"coarse": self.coarse.state_dict(), "fine": self.fine.state_dict()}
        save_weights_file(path, WEIGHTS_FORMAT, state, self.meta)

    @classmethod
    def load(cls, path: Path = WEIGHTS_PATH) -> KeypointDetector:
        """Load weights (data only, ``weights_only=True``); a bad file raises WeightsError."""
        state, meta = load_weights_file(path, WEIGHTS_FORMAT, WEIGHTS_HINT)
        try:
            coarse = KeypointNet(int(meta.get("coarse_width", COARSE_WIDTH)))
            fine = FineNet(int(meta.get("fine_width", FINE_WIDTH)))
        except (TypeError, ValueError) as exc:
            raise WeightsError(
                f"{path}: bad network widths in meta ({exc}); {WEIGHTS_HINT}"
            ) from None
        load_state(coarse, state.get("coarse"), path, WEIGHTS_HINT)
        load_state(fine, state.get("fine"), path, WEIGHTS_HINT)
        return cls(coarse.eval(), fine.eval(), meta)
