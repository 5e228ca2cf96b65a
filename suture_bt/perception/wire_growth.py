"""The needle mask grown along the wire where the network's coarse mask stopped short of it.

The coarse mask gates the colour test (:func:`~.colour_refine.refine_mask`), so wire the
network missed is left out even where the colour test sees it plainly. Grey pixels next to
the mask that are not in it count as an occluder (:mod:`occlusion`): a jaw or shaft in front.
Missed wire is then taken for an occluder that hides the needle, and any hypothesis may put
its unseen part there. On held-out development views of a needle held 37-41 mm from the
eyes the network's mask covered only the band and a stub of the wire; a pose 176 deg off
explained the stub as well as the truth explained the whole wire.

Grey pixels are wire, not an occluder, when they are as thin as the wire and joined to the
mask: jaws and shafts are thicker (:func:`~.colour_refine.remove_thick` drops them).
"""

from __future__ import annotations

import cv2
import numpy as np

from suture_bt.perception.colour_refine import ColourRule, needle_coloured, remove_thick
from suture_bt.perception.mask_view import MaskView

#: Wire half width (px) from which the thickness test runs at half resolution.
HALF_RES_MIN_HALF_WIDTH_PX = 4.0
#: Factor by which the searched margin widens while the grown wire runs out of it.
GROWTH_STEP = 3.0


def grown_along_wire(
    rgb: np.ndarray,
    view: MaskView,
    half_width_px: float,
    reach_px: float,
    rule: ColourRule | None = None,
) -> MaskView:
    """The mask plus the needle-coloured pixels no thicker than ``half_width_px`` (the widest
    the wire can look) that are joined to it and within ``reach_px`` (the needle's chord) of
    all of its pixels.

    The view comes back unchanged where no thin grey joins it (an empty view too). A grown
    view carries no occluder or free-space fields (they are marked after this step).
    """
    if not view.mask.any():
        return view
    rule = rule or ColourRule()
    H, W = rgb.shape[:2]
    h, w = view.mask.shape
    x0, y0 = view.origin
    ys, xs = np.nonzero(view.mask)
    # Every pixel of one needle lies within its chord (plus the wire's width) of every other.
    r = reach_px + half_width_px
    far = (
        max(x0 + xs.max() - r, 0),
        min(x0 + xs.min() + r + 1, W),
        max(y0 + ys.max() - r, 0),
        min(y0 + ys.min() + r + 1, H),
    )
    # Most views grow a little or nowhere: look in the mask's near surroundings first, and
    # farther only while the grown wire runs out of the window.
    limit = _window(view, far, rgb.shape)
    margin = 2 * half_width_px + 4
    grown = view
    while True:
        box = (
            max(x0 - margin, far[0]),
            min(x0 + w + margin, far[1]),
            max(y0 - margin, far[2]),
            min(y0 + h + margin, far[3]),
        )
        window = _window(view, box, rgb.shape)
        found = _grown(rgb, view, window, half_width_px, rule)
        if found is None:
            return grown
        grown = found
        if not _runs_out(found, window, limit):
            return grown
        margin *= GROWTH_STEP


def _window(view: MaskView, box, shape) -> tuple[int, int, int, int]:
    """The pixel window (a, b, c, d: columns a..b-1, rows c..d-1) of ``box`` (x0, x1, y0, y1),
    widened to hold the mask and clipped to the image."""
    H, W = shape[:2]
    h, w = view.mask.shape
    x0, y0 = view.origin
    a, b = int(max(min(box[0], x0), 0)), int(min(max(box[1], x0 + w), W))
    c, d = int(max(min(box[2], y0), 0)), int(min(max(box[3], y0 + h), H))
    return a, b, c, d


def _runs_out(view: MaskView, window, limit) -> bool:
    """Whether ``view`` reaches a side of ``window`` short of the same side of ``limit``."""
    a, b, c, d = window
    x0, y0 = view.origin
    h, w = view.mask.shape
    return (
        (x0 <= a and a > limit[0])
        or (x0 + w >= b and b < limit[1])
        or (y0 <= c and c > limit[2])
        or (y0 + h >= d and d < limit[3])
    )


def _grown(rgb, view: MaskView, window, half_width_px: float, rule: ColourRule):
    """The view grown within ``window`` (:func:`_window`); None when nothing joins it there."""
    a, b, c, d = window
    h, w = view.mask.shape
    x0, y0 = view.origin
    own = np.zeros((d - c, b - a), bool)
    own[y0 - c : y0 - c + h, x0 - a : x0 - a + w] = view.mask
    grey = needle_coloured(rgb[c:d, a:b], rule)
    thin = (grey & ~_thick(grey, half_width_px)) | own
    _, lab = cv2.connectedComponents(thin.astype(np.uint8), connectivity=8)
    joined = np.unique(lab[own])
    grown = np.isin(lab, joined[joined > 0])
    ys, xs = np.nonzero(grown)
    if len(xs) == int(view.mask.sum()):
        return None
    y_lo, y_hi, x_lo, x_hi = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    return MaskView(grown[y_lo:y_hi, x_lo:x_hi], (a + int(x_lo), c + int(y_lo)))


def _thick(grey: np.ndarray, half_width_px: float) -> np.ndarray:
    """Where ``grey`` is thicker than the wire (jaws, shafts; :func:`remove_thick`), found at
    half resolution when the wire may look 8 px wide or more (a quarter of the cost; the
    jaw's outline need not be exact, its core is grown past it) and one pixel wider there."""
    # Specks that fail the colour test inside a lit jaw face must not make it look thin.
    solid = cv2.morphologyEx(grey.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    if half_width_px < HALF_RES_MIN_HALF_WIDTH_PX:
        s = solid.astype(bool)
        return s & ~remove_thick(s, half_width_px)
    h, w = solid.shape
    small = cv2.resize(solid, ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA) > 0
    thick = (small & ~remove_thick(small, half_width_px / 2)).astype(np.uint8)
    thick = cv2.dilate(thick, np.ones((3, 3), np.uint8))
    return np.repeat(np.repeat(thick, 2, 0), 2, 1)[:h, :w].astype(bool)
