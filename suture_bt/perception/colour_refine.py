"""Coarse-to-fine needle mask: the coarse CNN mask gates a full-resolution colour test.

The needle is grey metal (blue ≥ red, also when saturated white at 2× brightness); the tissue
is pink (red well above blue) and the empty cavity is dark red. Inside a band around the
upsampled coarse mask, a pixel is needle when blue − red ≥ ``min_blue_minus_red`` and its
mean level ≥ ``min_level`` (40: sensor noise on a black shaft in shadow reaches the 30s, the
needle's darkest pixels stay above 50); a dark pixel must also be neutral (port holes and the
cavity in shadow are red-tinted; they had entered the masks of needles in a port). The
renderer does not anti-alias, so a per-pixel decision keeps the wire's edges where they are
(no blur, no bias). Those levels are the nominal exposure's; a dim frame scales them down
(:meth:`ColourRule.at_exposure`, :func:`frame_exposure`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from suture_bt.perception.pose_fit import MaskView
from suture_bt.perception.small_blobs import without_small_blobs


@dataclass(frozen=True)
class ColourRule:
    """Thresholds of the needle colour test (8-bit levels)."""

    min_blue_minus_red: float = -12.0
    min_level: float = 40.0
    #: Below this mean level a pixel must be neutral too (blue − red ≥ ``dark_min_blue_minus_red``):
    #: the needle in shadow stays grey, while the dark port holes and cavity are red-tinted.
    dark_level: float = 50.0
    dark_min_blue_minus_red: float = -4.0
    band_px: int = 9
    min_component_px: int = 4
    #: Tissue: red above blue by this much; cavity: level below ``min_level``.
    tissue_min_red_minus_blue: float = 30.0

    def at_exposure(self, exposure: float) -> ColourRule:
        """This rule for a frame exposed ``exposure`` × the nominal (:func:`frame_exposure`):
        in a dim frame (a low gain, a tilted light) the level thresholds and the tissue's red
        excess shrink with the light, down to ``EXPOSURE_FLOORS``; the colour margins are
        sensor noise and stay. A frame within ``EXPOSURE_KNEE`` of the nominal, or brighter
        (it saturates), keeps the nominal rule."""
        k = min(1.0, max(exposure, 0.0) / EXPOSURE_KNEE)
        if k >= 1.0:
            return self
        lo_level, lo_dark, lo_tissue = EXPOSURE_FLOORS
        return replace(
            self,
            min_level=max(k * self.min_level, lo_level),
            dark_level=max(k * self.dark_level, lo_dark),
            tissue_min_red_minus_blue=max(k * self.tissue_min_red_minus_blue, lo_tissue),
        )


#: 99th percentile of a frame's red channel (the lit tissue) at the nominal exposure (gain 1):
#: 182-211 × the gain over 60 frames of held-out phantom poses and lights tilted 0-40° from
#: overhead (session 31); higher with the light tilted, as one ridge flank faces it.
NOMINAL_RED_P99 = 195.0
#: Exposures above this share of the nominal keep the nominal rule (the estimate's own spread).
EXPOSURE_KNEE = 0.9
#: Lowest scaled min_level, dark_level and tissue red excess: above sensor noise on the black
#: shaft and the cavity in a dim frame (the needle's darkest pixels at gain 0.3 reach ~29).
EXPOSURE_FLOORS = (15.0, 20.0, 12.0)


def frame_exposure(rgb: np.ndarray) -> float:
    """A frame's exposure relative to the nominal: its lit tissue's red (99th percentile over
    every 4th pixel) over :data:`NOMINAL_RED_P99`. Bright instruments can only raise it, so a
    frame without tissue in view keeps the nominal rule."""
    return float(np.percentile(rgb[::4, ::4, 0], 99)) / NOMINAL_RED_P99


#: A pixel this violet (well above sensor noise on dim metal) is the swage band's.
BAND_PIXEL_SCORE = 0.45


def channel_sum(c: np.ndarray) -> np.ndarray:
    """R + G + B per pixel of colours (..., 3), added in that order: what ``c.sum(-1)`` gives,
    without numpy's slow reduction over an axis of three (a third of the colour tests' time).
    Integer colours give the same integers (int16 holds three 8-bit levels)."""
    return c[..., 0] + c[..., 1] + c[..., 2]


def violet_score(rgb: np.ndarray) -> np.ndarray:
    """Per pixel ((R + B)/2 − G) / level: ≈ 0.9 on the violet swage band, ≈ 0 on grey metal."""
    c = rgb.astype(np.float32)
    # The channels' float32 mean as numpy's ``mean(-1)`` makes it: the float32 sum over a
    # float64 count, stored as float32 (the same bits on every 8-bit colour, tested).
    level = np.maximum((channel_sum(c) / 3).astype(np.float32), 1.0)
    return (0.5 * (c[..., 0] + c[..., 2]) - c[..., 1]) / level


def tissue_coloured(c16: np.ndarray, rule: ColourRule) -> np.ndarray:
    """Pixels (int16 colours, ..., 3) of lit tissue: pink, red above blue, above the cavity's
    level."""
    level = channel_sum(c16) / 3.0
    return (c16[..., 0] - c16[..., 2] >= rule.tissue_min_red_minus_blue) & (level >= rule.min_level)


@functools.lru_cache(maxsize=64)
def _least_sum(level: float) -> int:
    """The least 8-bit channel sum whose mean (sum / 3.0, as float64) reaches ``level`` (766:
    none does)."""
    reach = np.arange(766) / 3.0 >= level
    return int(np.argmax(reach)) if reach.any() else 766


def needle_coloured(rgb: np.ndarray, rule: ColourRule) -> np.ndarray:
    """Pixels passing the needle colour test (grey metal: the needle and the instruments).

    8-bit images (..., H, W, 3) take the test in integers with OpenCV, about 4x faster and
    the same pixels (tested on every 8-bit colour): level ≥ L is channel sum ≥
    :func:`_least_sum` (L), blue − red ≥ t is blue − red ≥ ⌈t⌉."""
    if rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[-1] == 3:
        r, g, b = cv2.split(rgb)
        total = cv2.add(cv2.add(r, g, dtype=cv2.CV_16U), b, dtype=cv2.CV_16U)
        bmr = cv2.subtract(b, r, dtype=cv2.CV_16S)
        dark_ok = (total >= _least_sum(rule.dark_level)) | (
            bmr >= math.ceil(rule.dark_min_blue_minus_red)
        )
        lit = total >= _least_sum(rule.min_level)
        return (bmr >= math.ceil(rule.min_blue_minus_red)) & lit & dark_ok
    c = rgb.astype(np.int16)
    level = channel_sum(c) / 3.0
    bmr = c[..., 2] - c[..., 0]
    dark_ok = (level >= rule.dark_level) | (bmr >= rule.dark_min_blue_minus_red)
    return (bmr >= rule.min_blue_minus_red) & (level >= rule.min_level) & dark_ok


def coarse_components(
    prob: np.ndarray,
    threshold: float = 0.5,
    keep_ratio: float = 0.15,
    max_gap: float | None = None,
    anchors: np.ndarray | None = None,
):
    """Binary coarse mask: the needle's blob and pieces of it that occluders split off.

    The needle's blob is the one nearest the ``anchors`` (the network's end keypoints, in
    coarse px), else the largest; pieces are blobs ≥ ``keep_ratio`` of its area within
    ``max_gap`` px of it (pieces of one needle are never farther apart than its chord: a far
    blob is another instrument's tip). Empty when nothing passes the threshold.
    """
    m = (prob > threshold).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    if n <= 1:
        return np.zeros_like(m, bool)
    areas = stats[1:, cv2.CC_STAT_AREA]
    main = 1 + int(np.argmax(areas))
    if anchors is not None and len(anchors):
        ys, xs = np.nonzero(lab)
        d = np.hypot(xs[:, None] - anchors[None, :, 0], ys[:, None] - anchors[None, :, 1])
        near = np.full((n, len(anchors)), np.inf)
        np.minimum.at(near, lab[ys, xs], d)
        main = 1 + int(np.argmin(near[1:].sum(1)))
    keep = 1 + np.nonzero(areas >= keep_ratio * areas[main - 1])[0]
    if max_gap is not None and len(keep) > 1:
        dist = cv2.distanceTransform((lab != main).astype(np.uint8), cv2.DIST_L2, 3)
        keep = [k for k in keep if k == main or dist[lab == k].min() <= max_gap]
    return np.isin(lab, keep)


#: Least area of a thick core, in units of the squared gate half width (see remove_thick).
MIN_CORE_AREA = 0.25


def remove_thick(mask: np.ndarray, max_half_width_px: float) -> np.ndarray:
    """Drop blobs thicker than the wire (grey jaws, shaft) that touch the needle's mask.

    Pixels deeper than ``max_half_width_px`` inside the mask seed the thick parts, which are
    grown back by that depth (plus one pixel) and removed; the wire's pixels next to a jaw go
    with them, which the one-sided fit tolerates like any occlusion.
    """
    m = mask.astype(np.uint8)
    if not m.any():
        return mask
    dt = cv2.distanceTransform(np.pad(m, 1), cv2.DIST_L2, 5)[1:-1, 1:-1]
    core = (dt > max_half_width_px).astype(np.uint8)
    # A few deep pixels inside the wire itself (where it crosses itself or is rendered a
    # pixel fat) are not a jaw: cores smaller than a quarter of the gate's square are ignored.
    core = without_small_blobs(core, MIN_CORE_AREA * max_half_width_px**2).astype(np.uint8)
    if not core.any():
        return mask
    r = int(np.ceil(max_half_width_px)) + 2
    grown = cv2.dilate(core, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)))
    return mask & (grown == 0)


def refine_mask(
    rgb: np.ndarray,
    coarse: np.ndarray,
    scale: float,
    rule: ColourRule = ColourRule(),
    max_half_width_px: float | None = None,
) -> MaskView:
    """Full-resolution needle mask (a crop) from an RGB image and a coarse mask.

    ``coarse`` pixel (i, j) covers full-resolution pixels around ((j + 0.5)·scale − 0.5, …):
    ``scale`` is full-resolution pixels per coarse pixel. ``max_half_width_px`` (the wire's
    largest plausible half width in pixels) enables :func:`remove_thick`.
    """
    H, W = rgb.shape[:2]
    ys, xs = np.nonzero(coarse)
    if len(xs) == 0:
        return MaskView(np.zeros((0, 0), bool), (0, 0))
    pad = rule.band_px + scale
    x0 = int(max(np.floor(xs.min() * scale - pad), 0))
    x1 = int(min(np.ceil((xs.max() + 1) * scale + pad), W))
    y0 = int(max(np.floor(ys.min() * scale - pad), 0))
    y1 = int(min(np.ceil((ys.max() + 1) * scale + pad), H))
    # Coarse mask resampled onto the crop's pixel grid, then dilated by the band.
    gx = ((np.arange(x0, x1) + 0.5) / scale - 0.5).round().astype(int).clip(0, coarse.shape[1] - 1)
    gy = ((np.arange(y0, y1) + 0.5) / scale - 0.5).round().astype(int).clip(0, coarse.shape[0] - 1)
    gate = coarse[np.ix_(gy, gx)].astype(np.uint8)
    k = 2 * rule.band_px + 1
    gate = cv2.dilate(gate, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
    needle = needle_coloured(rgb[y0:y1, x0:x1], rule)
    return drop_thick(MaskView(needle & gate, (x0, y0)), max_half_width_px, rule)


def drop_thick(
    view: MaskView, max_half_width_px: float | None, rule: ColourRule = ColourRule()
) -> MaskView:
    """The mask without blobs thicker than ``max_half_width_px`` (if given, see
    :func:`remove_thick`) and without specks smaller than ``rule.min_component_px``."""
    m = view.mask
    if max_half_width_px is not None:
        m = remove_thick(m, max_half_width_px)
    return MaskView(without_small_blobs(m, rule.min_component_px), view.origin)


def free_space_dt(
    rgb: np.ndarray, view: MaskView, margin: float = 0.6, rule: ColourRule = ColourRule()
) -> tuple[np.ndarray, tuple[int, int]]:
    """Distance (px) from each certainly-needle-free pixel to the nearest pixel that is not,
    over the mask's box grown by ``margin`` of its size; (map, its top-left pixel).

    Certainly free = fails the needle colour test (tissue, cavity, dark background). Grey
    pixels (needle, arms, jaws: possible occluders) are not free.
    """
    H, W = rgb.shape[:2]
    h, w = view.mask.shape
    x0, y0 = view.origin
    mx, my = int(margin * max(w, h)) + 4, int(margin * max(w, h)) + 4
    a, b = max(x0 - mx, 0), min(x0 + w + mx, W)
    c, d = max(y0 - my, 0), min(y0 + h + my, H)
    free = (~needle_coloured(rgb[c:d, a:b], rule)).astype(np.uint8)
    return cv2.distanceTransform(free, cv2.DIST_L2, 3), (a, c)
