"""Multi-task needle CNN: shared encoder, needle-mask head, base/tip keypoint heatmap heads.

A small U-Net (128 k parameters, 0.5 MB) that runs on a downsampled image (default 480×272).
Outputs at half the input resolution: channel 0 the coarse needle-mask logit, channel 1 a
heatmap of both needle ends (found even where the base band is hidden), channel 2 a heatmap
of the base.
Peaks are decoded to sub-pixel positions (:func:`decode_ends`).
Weights load with ``torch.load(weights_only=True)``; a missing or mismatched file raises
:class:`WeightsError` naming the file.
"""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F
from torch.nn.utils.fusion import fuse_conv_bn_eval

#: Network input size (width, height) used for training and inference.
INPUT_SIZE = (480, 272)
#: Output stride relative to the network input.
OUTPUT_STRIDE = 2
DEFAULT_WEIGHTS = Path(__file__).with_name("weights") / "needle_net.pt"
WEIGHTS_FORMAT = "suture_bt.needle_net.v2"


class WeightsError(RuntimeError):
    """The needle network's weights file is missing or does not match the architecture."""


def _block(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride, 1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


def _sep(cin: int, cout: int) -> nn.Sequential:
    """Depthwise-separable 3×3 conv block (cheap on a CPU)."""
    return nn.Sequential(
        nn.Conv2d(cin, cin, 3, 1, 1, groups=cin, bias=False),
        nn.Conv2d(cin, cout, 1, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class NeedleNet(nn.Module):
    """Encoder (strides 2-16) and a light decoder back to stride 2; 3 output channels."""

    def __init__(self, width: int = 16) -> None:
        super().__init__()
        c1, c2, c3, c4 = width, 2 * width, 4 * width, 6 * width
        self.width = width
        self.enc1 = nn.Sequential(_block(3, c1, 2), _sep(c1, c1))
        self.enc2 = nn.Sequential(_block(c1, c2, 2), _sep(c2, c2))
        self.enc3 = nn.Sequential(_block(c2, c3, 2), _sep(c3, c3))
        self.enc4 = nn.Sequential(_block(c3, c4, 2), _sep(c4, c4), _sep(c4, c4))
        self.lat3 = nn.Conv2d(c3, c4, 1)
        self.dec3 = _sep(c4, c3)
        self.lat2 = nn.Conv2d(c2, c3, 1)
        self.dec2 = _sep(c3, c2)
        self.lat1 = nn.Conv2d(c1, c2, 1)
        self.dec1 = nn.Sequential(_sep(c2, c1), nn.Conv2d(c1, c1, 3, 1, 1), nn.ReLU(inplace=True))
        self.head = nn.Conv2d(c1, 3, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W) float in [0, 1] → (B, 3, H/2, W/2) logits (mask, base, tip)."""
        e1 = self.enc1(x)
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        e4 = self.enc4(e3)
        d3 = self.dec3(_add_upsampled(self.lat3(e3), e4))
        d2 = self.dec2(_add_upsampled(self.lat2(e2), d3))
        d1 = self.dec1(_add_upsampled(self.lat1(e1), d2))
        return self.head(d1)


def _add_upsampled(lat: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """``lat`` + ``x`` upsampled (nearest) to its size: the decoder's skip join.

    Without autograd, channels-last and exactly twice the size (every join at the network's
    input sizes), ``x`` is added in place through a broadcast view of ``lat``: the same sums
    (the same bits) without the upsampled copy and a second output (on a CPU the join took a
    third of the network's time).
    """
    B, C, H, W = lat.shape
    h, w = x.shape[-2:]
    cl = torch.channels_last
    if (
        torch.is_grad_enabled()
        or (H, W) != (2 * h, 2 * w)
        or not lat.is_contiguous(memory_format=cl)
        or not x.is_contiguous(memory_format=cl)
    ):
        return lat + F.interpolate(x, size=(H, W), mode="nearest")
    view = lat.permute(0, 2, 3, 1).view(B, h, 2, w, 2, C)
    view += x.permute(0, 2, 3, 1)[:, :, None, :, None, :]
    return lat


def for_inference(net: NeedleNet) -> NeedleNet:
    """An evaluation copy with each BatchNorm folded into its convolution, in channels-last
    memory: the same outputs (to float rounding), about twice as fast on a CPU."""
    net = copy.deepcopy(net).eval()
    for mod in net.modules():
        if isinstance(mod, nn.Sequential):
            names = list(mod._modules)
            for a, b in zip(names, names[1:], strict=False):
                conv, bn = mod._modules[a], mod._modules[b]
                if isinstance(conv, nn.Conv2d) and isinstance(bn, nn.BatchNorm2d):
                    mod._modules[a] = fuse_conv_bn_eval(conv, bn)
                    mod._modules[b] = nn.Identity()
    return net.to(memory_format=torch.channels_last)


class FrozenByShape:
    """The inference network as a TorchScript graph frozen for each input shape, traced on
    the shape's first call without autograd (about 0.17 s, once): constants folded and the
    Python of every module call gone, 10.8 → 8.0 ms an eye at 480×272 on this 2-core CPU, the
    same bits (checked on the first call of each shape; a graph that differs, or fails to
    build, leaves that shape to the module). With autograd on, the module itself runs. Only
    for modules whose control flow depends on nothing but the input's shape, type and memory
    layout (the key of a graph), as :class:`NeedleNet`'s does."""

    def __init__(self, module: nn.Module) -> None:
        self.module = module
        self._graphs: dict = {}

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled():
            return self.module(x)
        cl = x.is_contiguous(memory_format=torch.channels_last)
        key = (tuple(x.shape), x.dtype, cl)
        if key not in self._graphs:
            self._graphs[key] = self._frozen(x)
        return self._graphs[key](x)

    def _frozen(self, x: torch.Tensor):
        """A frozen graph for x's shape, or the module where the graph is not the same."""
        try:
            with warnings.catch_warnings(), torch.inference_mode(False), torch.no_grad():
                warnings.simplefilter("ignore")  # the traced join's shape test is constant
                sample = x.detach().clone()  # a normal tensor, even from inference mode
                graph = torch.jit.freeze(torch.jit.trace(self.module, sample, check_trace=False))
                same = torch.equal(graph(sample), self.module(sample))
        except Exception:  # noqa: BLE001 - any failure to build: the module is the answer
            return self.module
        return graph if same else self.module


def frozen_for_inference(net: NeedleNet) -> FrozenByShape:
    """:func:`for_inference`'s copy run as :class:`FrozenByShape` graphs."""
    return FrozenByShape(for_inference(net))


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())


def to_input(rgb: np.ndarray) -> torch.Tensor:
    """An RGB uint8 image (H, W, 3) at the network input size → (1, 3, H, W) float tensor."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an H×W×3 RGB image, got shape {rgb.shape}")
    t = torch.from_numpy(np.ascontiguousarray(rgb)).permute(2, 0, 1).float().div_(255.0)
    return t[None]


def decode_keypoints(heat: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel peaks of heatmap logits (B, K, h, w): (B, K, 2) (u, v) in output pixels, scores.

    A parabola through the log-probabilities at the arg-max and its 4-neighbours (exact for a
    Gaussian peak); the score is the peak probability.
    """
    B, K, h, w = heat.shape
    logp = F.logsigmoid(heat).reshape(B * K, h, w).numpy().astype(np.float64)
    idx = logp.reshape(B * K, -1).argmax(1)
    v0, u0 = idx // w, idx % w
    out = np.zeros((B * K, 2))
    score = np.exp(logp.reshape(B * K, -1)[np.arange(B * K), idx])
    for i in range(B * K):
        off = []
        for axis, (c, n) in enumerate(((u0[i], w), (v0[i], h))):
            if 0 < c < n - 1:
                if axis == 0:
                    lm, l0, lp = logp[i, v0[i], c - 1 : c + 2]
                else:
                    lm, l0, lp = logp[i, c - 1 : c + 2, u0[i]]
                den = lm - 2 * l0 + lp
                off.append(float(np.clip(0.5 * (lm - lp) / den, -0.5, 0.5)) if den < 0 else 0.0)
            else:
                off.append(0.0)
        out[i] = (u0[i] + off[0], v0[i] + off[1])
    return out.reshape(B, K, 2), score.reshape(B, K)


def decode_ends(
    ends_logits: torch.Tensor, base_logits: torch.Tensor, suppress: int = 4
) -> tuple[np.ndarray, np.ndarray]:
    """The two needle ends (B, 2, 2) in output pixels, ordered (base, tip), and their scores.

    Two peaks of the both-ends heatmap (the second outside ``suppress`` pixels of the first),
    each sub-pixel; the one where the base heatmap is higher is called the base.
    """
    B, h, w = ends_logits.shape
    first, s1 = decode_keypoints(ends_logits[:, None])
    masked = ends_logits.clone()
    yy = torch.arange(h)[:, None]
    xx = torch.arange(w)[None, :]
    for b in range(B):
        u, v = first[b, 0]
        near = (xx - u) ** 2 + (yy - v) ** 2 <= suppress**2
        masked[b][near] = -1e4
    second, s2 = decode_keypoints(masked[:, None])
    ends = np.concatenate([first, second], 1)
    scores = np.concatenate([s1, s2], 1)
    base_p = torch.sigmoid(base_logits).numpy()
    for b in range(B):
        at = [base_p[b, int(round(v)), int(round(u))] for u, v in ends[b]]
        if at[1] > at[0]:
            ends[b] = ends[b, ::-1]
            scores[b] = scores[b, ::-1]
    return ends, scores


def save_weights(net: NeedleNet, path: Path, meta: dict | None = None) -> None:
    """Write the state dict with a format tag and the architecture width."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(
        {
            "format": WEIGHTS_FORMAT,
            "width": net.width,
            "state_dict": net.state_dict(),
            "meta": dict(meta or {}),
        },
        path,
    )


def load_network(path: Path | str | None = None) -> NeedleNet:
    """The trained network in eval mode (default: the weights shipped in the package)."""
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    if not path.is_file():
        raise WeightsError(
            f"needle network weights not found: {path} "
            "(train them with `suture-bt train needle`, see README)"
        )
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is reported the same way
        raise WeightsError(f"cannot read needle network weights {path}: {exc}") from exc
    if not isinstance(blob, dict) or blob.get("format") != WEIGHTS_FORMAT:
        raise WeightsError(f"{path} is not a needle-network weights file ({WEIGHTS_FORMAT})")
    net = NeedleNet(width=int(blob.get("width", 16)))
    try:
        net.load_state_dict(blob["state_dict"])
    except (RuntimeError, KeyError) as exc:
        raise WeightsError(f"weights in {path} do not match the network: {exc}") from exc
    net.eval()
    return net
