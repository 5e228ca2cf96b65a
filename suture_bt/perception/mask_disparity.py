"""Stereo disparity of a needle mask: the horizontal shift that best overlays the two eyes' masks.

The endoscope's two cameras are parallel and side by side, so a point at depth z appears
d = f·b/z pixels further right in the left image than in the right one, on the same row. The
shift maximising the overlap of the two masks gives the depth of what they show, without
trusting keypoints (which may sit on a jaw or be matched to the wrong end). Used to size the
thickness gate that drops jaws and shafts from the needle mask.
"""

from __future__ import annotations

import numpy as np

from suture_bt.perception.pose_fit import MaskView

#: Least share of the smaller mask that must overlap at the best shift to trust it.
MIN_OVERLAP = 0.3


def _in_box(view: MaskView, x0: int, y0: int, w: int, h: int) -> np.ndarray:
    """The mask pasted into a (h, w) float array whose top-left pixel is (x0, y0)."""
    out = np.zeros((h, w), np.float64)
    m = np.asarray(view.mask, bool)
    ox, oy = view.origin[0] - x0, view.origin[1] - y0
    out[oy : oy + m.shape[0], ox : ox + m.shape[1]] = m
    return out


def mask_disparity(left: MaskView, right: MaskView, d_min: float, d_max: float) -> float | None:
    """Disparity (px, left u − right u) in [d_min, d_max] that best overlays the masks.

    Row-wise cross-correlation by FFT, summed over rows; ``None`` when either mask is empty
    or the best overlay covers less than :data:`MIN_OVERLAP` of the smaller mask.
    """
    nl, nr = int(np.sum(left.mask)), int(np.sum(right.mask))
    if nl == 0 or nr == 0:
        return None
    boxes = []
    for v in (left, right):
        h, w = v.mask.shape
        boxes.append((v.origin[0], v.origin[1], v.origin[0] + w, v.origin[1] + h))
    x0, y0 = min(b[0] for b in boxes), min(b[1] for b in boxes)
    x1, y1 = max(b[2] for b in boxes), max(b[3] for b in boxes)
    w, h = x1 - x0, y1 - y0
    L, R = _in_box(left, x0, y0, w, h), _in_box(right, x0, y0, w, h)
    n = int(2 ** np.ceil(np.log2(2 * w + 1)))
    # overlap(d) = Σ_rows Σ_u L[r, u] · R[r, u − d]
    spec = np.fft.rfft(L, n, axis=1) * np.conj(np.fft.rfft(R, n, axis=1))
    corr = np.fft.irfft(spec.sum(0), n)
    d = np.arange(int(np.floor(d_min)), int(np.ceil(d_max)) + 1)
    d = d[(d > -n // 2) & (d < n // 2)]
    if not len(d):
        return None
    overlap = corr[d % n]
    k = int(np.argmax(overlap))
    if overlap[k] < MIN_OVERLAP * min(nl, nr):
        return None
    if 0 < k < len(d) - 1:  # sub-pixel: parabola through the peak and its neighbours
        a, b, c = overlap[k - 1 : k + 2]
        den = a - 2 * b + c
        return float(d[k] + (0.5 * (a - c) / den if den < 0 else 0.0))
    return float(d[k])
