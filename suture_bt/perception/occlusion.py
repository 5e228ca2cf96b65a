"""Occluded needle ends: where the mask stops at a grey occluder, the needle may go on behind it.

The fit's one-sided objective explains every visible edge equally well with the needle ending
at the occluder (seen more end-on) or continuing behind it, and the fit started from the visible
ends finds the first. So a visible end that touches grey, non-needle pixels (a jaw or shaft) or
the image border is flagged, and the fit is re-started with that end pushed on behind the
occluder; the lower edge cost wins.
"""

from __future__ import annotations

import numpy as np

from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.pose_fit import MaskView

#: Extensions (fractions of the visible chord) tried for an occluded end.
EXTENSIONS = (0.35, 0.7)


def needle_coloured(rgb: np.ndarray, rule: ColourRule) -> np.ndarray:
    """Pixels passing the needle colour test (grey metal: the needle and the instruments)."""
    c = rgb.astype(np.int16)
    level = c.sum(-1) / 3.0
    return (c[..., 2] - c[..., 0] >= rule.min_blue_minus_red) & (level >= rule.min_level)


def end_is_occluded(
    rgb: np.ndarray, view: MaskView, uv: np.ndarray, radius: float, rule: ColourRule
) -> bool:
    """True when grey pixels that are not in the needle mask, or the image border, lie within
    ``radius`` px of the end pixel ``uv``."""
    H, W = rgb.shape[:2]
    u, v = float(uv[0]), float(uv[1])
    r = int(np.ceil(radius))
    a, b = int(np.floor(u)) - r, int(np.floor(u)) + r + 2
    c, d = int(np.floor(v)) - r, int(np.floor(v)) + r + 2
    if a < 0 or c < 0 or b > W or d > H:
        return True
    grey = needle_coloured(rgb[c:d, a:b], rule)
    x0, y0 = view.origin
    h, w = view.mask.shape
    mask = np.zeros_like(grey)
    ma, mb, mc, md = max(a - x0, 0), min(b - x0, w), max(c - y0, 0), min(d - y0, h)
    if ma < mb and mc < md:
        mask[mc + y0 - c : md + y0 - c, ma + x0 - a : mb + x0 - a] = view.mask[mc:md, ma:mb]
    yy, xx = np.mgrid[c:d, a:b]
    near = (xx - u) ** 2 + (yy - v) ** 2 <= radius**2
    return bool(np.any(grey & ~mask & near))


def extended_ends(
    ends: tuple[np.ndarray, np.ndarray], occluded: tuple[bool, bool]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """End-pixel hypotheses with each occluded end pushed outwards along the chord."""
    a, b = (np.asarray(e, float) for e in ends)
    chord = b - a
    out = []
    for k in EXTENSIONS:
        if occluded[0]:
            out.append((a - k * chord, b))
        if occluded[1]:
            out.append((a, b + k * chord))
    return out
