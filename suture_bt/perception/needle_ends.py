"""Which end is the base: the violet swage band (where the suture is attached) against grey metal.

The pose fit explains the needle's outline, which is the same for a pose and its base↔tip swap
(a half turn about the arc's bisector). The base end carries a violet band, so the colour of
the mask's pixels near each fitted end decides between the two: violet = (red + blue)/2 −
green, relative to the pixel's level, is about 0.9 on the band and about 0 on the metal, at any
brightness. A fitted end that touches an occluder only votes when it is violet (its grey may be
the wire next to a hidden band). Band pieces that a jaw cuts off from the rest of the needle
are put back into the mask (:func:`with_band_pieces`): the band is the most telling piece.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import CameraModel
from suture_bt.perception.colour_refine import (
    BAND_PIXEL_SCORE,
    ColourRule,
    needle_coloured,
    violet_score,
)
from suture_bt.perception.needle_projection import end_pixels, project_cam, transform_points
from suture_bt.perception.pose_fit import MaskView
from suture_bt.transforms import invert

#: Arc length around each end whose pixels are compared (m): inside the 3 mm band.
END_ARC = 0.002
#: Fewest mask pixels near an end for its colour to count.
MIN_END_PIXELS = 3
#: Violet score between grey metal (≈ 0) and the band (0.6-0.9 from dim to saturated light).
VIOLET_THRESHOLD = 0.3
#: |evidence| below this is undecided (the band is hidden or too small to see).
MIN_EVIDENCE = 0.15
#: Fewest band pixels in one eye for their position to vote.
MIN_BAND_PIXELS = 6


#: Largest band piece (px) relative to the band's area seen at the given depth: a bigger violet
#: blob is not the band.
MAX_BAND_AREA_RATIO = 2.0
#: The band's length along the wire (m): the swage end of the needle.
BAND_LENGTH = 0.003
#: Block size (px) of the cheap first look for violet, and the block score that is looked at
#: closer (a band piece covering a quarter of a grey block still scores about 0.17).
BAND_BLOCK = 4
BAND_BLOCK_SCORE = 0.12
#: Blue above green in a violet-looking block (8-bit levels): the band is far bluer than green
#: (about +110), the dark red cavity and pink tissue are not (about 0 and −10).
BAND_BLOCK_MIN_BLUE_MINUS_GREEN = 10.0


def _violet_candidates(crop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (rows, cols) of ``crop`` in, or next to, violet-looking BAND_BLOCK blocks: a
    cheap first look on the area-averaged image, so the exact test sees few pixels."""
    f = BAND_BLOCK
    hs, ws = crop.shape[0] // f, crop.shape[1] // f
    if hs == 0 or ws == 0:
        return np.zeros(0, int), np.zeros(0, int)
    small = cv2.resize(crop[: hs * f, : ws * f], (ws, hs), interpolation=cv2.INTER_AREA)
    s16 = small.astype(np.int16)
    hit = (violet_score(small) > BAND_BLOCK_SCORE) & (
        s16[..., 2] - s16[..., 1] >= BAND_BLOCK_MIN_BLUE_MINUS_GREEN
    )
    if not hit.any():
        return np.zeros(0, int), np.zeros(0, int)
    hit = cv2.dilate(hit.astype(np.uint8), np.ones((3, 3), np.uint8))
    by, bx = np.nonzero(hit)
    dy, dx = np.mgrid[0:f, 0:f]
    return (by[:, None] * f + dy.ravel()).ravel(), (bx[:, None] * f + dx.ravel()).ravel()


def with_band_pieces(
    rgb: np.ndarray,
    view: MaskView,
    reach_px: float,
    min_depth: float,
    cam: CameraModel,
    wire_radius: float,
    rule: ColourRule | None = None,
) -> MaskView:
    """The mask plus violet band pieces within ``reach_px`` of its box.

    The network's coarse mask can miss the band where a jaw cuts it off from the rest of the
    needle (a small piece on its own); the band is the needle's base end, so it is the most
    telling piece of all. A piece counts when it is violet, passes the needle colour test, has
    at least ``MIN_BAND_PIXELS`` pixels and is no larger than the band can look at ``min_depth``.
    """
    rule = rule or ColourRule()
    H, W = rgb.shape[:2]
    h, w = view.mask.shape
    if h == 0 or w == 0:
        return view
    x0, y0 = view.origin
    r = int(np.ceil(reach_px))
    a, b = max(x0 - r, 0), min(x0 + w + r, W)
    c, d = max(y0 - r, 0), min(y0 + h + r, H)
    crop = rgb[c:d, a:b]
    ys, xs = _violet_candidates(crop)
    if len(xs) < MIN_BAND_PIXELS:
        return view
    pix = crop[ys, xs]
    ok = (violet_score(pix) > BAND_PIXEL_SCORE) & needle_coloured(pix[None], rule)[0]
    ys, xs = ys[ok], xs[ok]
    if len(xs) < MIN_BAND_PIXELS:
        return view
    # Band pieces: components of those pixels (in their bounding box) of a plausible size.
    by0, bx0 = int(ys.min()), int(xs.min())
    band = np.zeros((int(ys.max()) - by0 + 1, int(xs.max()) - bx0 + 1), np.uint8)
    band[ys - by0, xs - bx0] = 1
    _, lab, stats, _ = cv2.connectedComponentsWithStats(band, connectivity=8)
    max_area = MAX_BAND_AREA_RATIO * BAND_LENGTH * 2.0 * wire_radius * (cam.fx / min_depth) ** 2
    area = stats[1:, cv2.CC_STAT_AREA]
    keep = 1 + np.nonzero((area >= MIN_BAND_PIXELS) & (area <= max_area))[0]
    if len(keep) == 0:
        return view
    py, px = np.nonzero(np.isin(lab, keep))
    py, px = py + by0 + c, px + bx0 + a  # image pixels
    # The union of the mask and the pieces, cropped to both.
    u0, v0 = min(x0, int(px.min())), min(y0, int(py.min()))
    u1, v1 = max(x0 + w, int(px.max()) + 1), max(y0 + h, int(py.max()) + 1)
    out = np.zeros((v1 - v0, u1 - u0), bool)
    out[y0 - v0 : y0 - v0 + h, x0 - u0 : x0 - u0 + w] = view.mask
    if out[py - v0, px - u0].all():
        return view
    out[py - v0, px - u0] = True
    return MaskView(out, (u0, v0))


def _end_score(
    rgb: np.ndarray, view: MaskView, cam: CameraModel, T_cam_needle: np.ndarray, arcs: np.ndarray
) -> float | None:
    """Median violet score of the mask pixels nearest the projected arc samples; None if few."""
    pts = arcs @ T_cam_needle[:3, :3].T + T_cam_needle[:3, 3]
    if np.any(pts[:, 2] <= 0):
        return None
    uv = np.stack(
        [cam.fx * pts[:, 0] / pts[:, 2] + cam.cx, cam.fy * pts[:, 1] / pts[:, 2] + cam.cy], 1
    )
    x0, y0 = view.origin
    h, w = view.mask.shape
    radius = max(2.0, 1.5 * cam.fx * 0.00036 / float(pts[:, 2].mean()))
    lo = np.floor(uv.min(0) - radius).astype(int)
    hi = np.ceil(uv.max(0) + radius).astype(int) + 1
    a, b = max(lo[0] - x0, 0), min(hi[0] - x0, w)
    c, d = max(lo[1] - y0, 0), min(hi[1] - y0, h)
    if a >= b or c >= d:
        return None
    vv, uu = np.nonzero(view.mask[c:d, a:b])
    if len(uu) == 0:
        return None
    pix = np.stack([uu + a + x0, vv + c + y0], 1).astype(float)
    dist = np.min(np.linalg.norm(pix[:, None] - uv[None], axis=-1), 1)
    near = dist <= radius
    if near.sum() < MIN_END_PIXELS:
        return None
    sel = pix[near].astype(int)
    return float(np.median(violet_score(rgb[sel[:, 1], sel[:, 0]])))


def band_pixels(rgb: np.ndarray, view: MaskView) -> np.ndarray | None:
    """The mask's violet (band) pixels as (u, v) rows; None when fewer than MIN_BAND_PIXELS."""
    ys, xs = np.nonzero(view.mask)
    if len(xs) == 0:
        return None
    pix = rgb[ys + view.origin[1], xs + view.origin[0]]
    band = violet_score(pix) > BAND_PIXEL_SCORE
    if band.sum() < MIN_BAND_PIXELS:
        return None
    return np.stack([xs[band] + view.origin[0], ys[band] + view.origin[1]], 1).astype(float)


def _band_position_vote(
    rgb: np.ndarray, view: MaskView, cam: CameraModel, T_cam_needle: np.ndarray, model
) -> float | None:
    """+1..−1: the mask's violet pixels lie nearer the fitted base end than the fitted tip.

    Unlike the end scores this needs only a rough fit (a pose a few pixels off, e.g. a needle
    seen edge-on), since the ends are far apart compared with the fit's error.
    """
    p = band_pixels(rgb, view)
    if p is None:
        return None
    ends = transform_points(T_cam_needle, np.stack([model.base, model.tip]))
    if np.any(ends[:, 2] <= 0):
        return None
    uv = project_cam(cam, ends)
    d_base = float(np.median(np.linalg.norm(p - uv[0], axis=1)))
    d_tip = float(np.median(np.linalg.norm(p - uv[1], axis=1)))
    return float(np.clip((d_tip - d_base) / max(d_tip + d_base, 1.0), -1.0, 1.0))


def _squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, M) squared distances between pixel rows a (N, 2) and b (M, 2); the same numbers as
    summing the squared differences over the last axis, without its slow size-2 reduction."""
    return (a[:, None, 0] - b[None, :, 0]) ** 2 + (a[:, None, 1] - b[None, :, 1]) ** 2


def _in_eye(cam: CameraModel, first: CameraModel, T_first_needle: np.ndarray) -> np.ndarray:
    """The needle pose in ``cam``'s frame, given it in the ``first`` camera's frame."""
    return invert(cam.T_world_cam) @ first.T_world_cam @ T_first_needle


#: Share of the band's pixels allowed nearer the base than the offset :func:`band_offset`
#: reports (a few stray violet pixels must not hide a slid fit).
BAND_OFFSET_QUANTILE = 10


def band_offset(
    images: tuple[np.ndarray, np.ndarray],
    views: tuple[MaskView, MaskView],
    cams: tuple[CameraModel, CameraModel],
    T_cam_needle: np.ndarray,
    model: NeedleModel,
    samples: int = 100,
) -> float | None:
    """How far (m, along the arc) the seen swage band starts from the fitted base: the
    BAND_OFFSET_QUANTILE-th percentile of the violet pixels' nearest arc positions, the larger
    over the eyes that see the band; None when neither does. ``samples`` along the arc (0.2 mm
    apart by default) are enough for a threshold of millimetres.

    The band covers the first BAND_LENGTH of the arc, so a right pose puts it at 0-3 mm. A
    pose slid along its own circle (the visible piece explained by another stretch of it, the
    real end taken for a cut) puts it further in.
    """
    angles = np.linspace(model.base_angle, model.tip_angle, samples)
    along = np.abs(angles - model.base_angle) * model.radius
    arc = model.point_at(angles)
    offsets = []
    for rgb, view, cam in zip(images, views, cams, strict=True):
        p = band_pixels(rgb, view)
        if p is None:
            continue
        T = _in_eye(cam, cams[0], T_cam_needle)
        pts = transform_points(T, arc)
        if np.any(pts[:, 2] <= 0):
            continue
        uv = project_cam(cam, pts)
        nearest = np.argmin(_squared_distances(p, uv), 1)
        offsets.append(float(np.percentile(along[nearest], BAND_OFFSET_QUANTILE)))
    return max(offsets) if offsets else None


#: Blue above green (8-bit levels) of a band pixel looked for outside the needle mask: the
#: violet score alone also passes the dark red of the cavity and shadowed tissue (blue about
#: level with green there, about +110 on the band).
BAND_MIN_BLUE_MINUS_GREEN = 40
#: Violet pixels the band miss is measured on (evenly strided): enough for a median.
MAX_BAND_SAMPLES = 256


def band_miss_px(
    images: tuple[np.ndarray, np.ndarray],
    cams: tuple[CameraModel, CameraModel],
    T_cam_needle: np.ndarray,
    model: NeedleModel,
    reach_px: float,
    samples: int = 400,
) -> float | None:
    """How far (px) the swage band seen near the fitted base lies off the fitted arc: the
    median distance of the violet pixels within ``reach_px`` of the fitted band's projection
    (the arc's first BAND_LENGTH) to the whole arc's projection, the larger over the eyes that
    see at least MIN_BAND_PIXELS of them; None when neither does.

    The pixels are looked for in the image, not the needle mask (violet and clearly bluer
    than green): a band cut off from the seen piece by an occluder is left out of the mask,
    yet it still shows where the base is.
    A right pose runs through it (its pixels lie within the wire's half width of the
    centre-line); a pose whose seen piece fits while its hidden part swings elsewhere leaves
    the band beside its arc."""
    angles = np.linspace(model.base_angle, model.tip_angle, samples)
    arc = model.point_at(angles)
    in_band = np.abs(angles - model.base_angle) * model.radius <= BAND_LENGTH
    misses = []
    for rgb, cam in zip(images, cams, strict=True):
        pts = transform_points(_in_eye(cam, cams[0], T_cam_needle), arc)
        if np.any(pts[:, 2] <= 0):
            continue
        uv = project_cam(cam, pts)
        lo = np.floor(uv[in_band].min(0) - reach_px).astype(int)
        hi = np.ceil(uv[in_band].max(0) + reach_px).astype(int) + 1
        lo, hi = np.maximum(lo, 0), np.minimum(hi, (rgb.shape[1], rgb.shape[0]))
        if np.any(hi <= lo):
            continue
        crop = rgb[lo[1] : hi[1], lo[0] : hi[0]]
        # the cheap integer test first; the violet score only on the few pixels it keeps
        bluer = crop[..., 2].astype(np.int16) - crop[..., 1] >= BAND_MIN_BLUE_MINUS_GREEN
        ys, xs = np.nonzero(bluer)
        violet = violet_score(crop[ys, xs]) > BAND_PIXEL_SCORE
        p = np.stack([xs[violet] + lo[0], ys[violet] + lo[1]], 1).astype(float)
        p = p[:: -(-len(p) // MAX_BAND_SAMPLES) or 1]  # a near band is thousands of pixels
        to_band = np.sqrt(_squared_distances(p, uv[in_band]).min(1))
        p = p[to_band <= reach_px]
        if len(p) < MIN_BAND_PIXELS:
            continue
        d = np.sqrt(_squared_distances(p, uv).min(1))
        misses.append(float(np.median(d)))
    return max(misses) if misses else None


def base_evidence(
    images: tuple[np.ndarray, np.ndarray],
    views: tuple[MaskView, MaskView],
    cams: tuple[CameraModel, CameraModel],
    T_cam_needle: np.ndarray,
    model: NeedleModel,
    end_hidden: Callable[[int, np.ndarray], bool] | None = None,
    ends_cut: tuple[bool, bool] = (False, False),
) -> float:
    """Mean vote of both eyes: violet at the fitted base, grey at the fitted tip and violet
    pixels nearer the fitted base than the tip vote > 0 (base and tip right), the opposite < 0
    (swapped); 0 when nothing is seen.

    ``ends_cut`` (base, tip): the fitted end is where the wire goes into something known to
    hide it (the tissue: the needle may go on inside), so grey there does not vote either.

    ``T_cam_needle`` is in the first camera's frame; ``cams[1]`` is placed relative to it.
    ``end_hidden(eye, uv)`` tells whether an end pixel touches an occluder: grey there only
    says the band is out of sight, so it does not vote (violet still does).
    """
    n = max(3, int(np.ceil(END_ARC / model.radius / 0.02)))
    da = END_ARC / model.radius
    base_arc = model.point_at(np.linspace(model.base_angle - da, model.base_angle, n))
    tip_arc = model.point_at(np.linspace(model.tip_angle, model.tip_angle + da, n))
    votes = []
    for eye, (rgb, view, cam) in enumerate(zip(images, views, cams, strict=True)):
        T = _in_eye(cam, cams[0], T_cam_needle)
        sb = _end_score(rgb, view, cam, T, base_arc)
        st = _end_score(rgb, view, cam, T, tip_arc)
        if end_hidden is not None:
            ends_uv = end_pixels(cam, T, model)
            if sb is not None and sb < VIOLET_THRESHOLD and end_hidden(eye, ends_uv[0]):
                sb = None
            if st is not None and st < VIOLET_THRESHOLD and end_hidden(eye, ends_uv[1]):
                st = None
        if sb is not None and sb < VIOLET_THRESHOLD and ends_cut[0]:
            sb = None
        if st is not None and st < VIOLET_THRESHOLD and ends_cut[1]:
            st = None
        # Each visible end votes: violet where the fit put the base, grey where it put the tip.
        if sb is not None:
            votes.append(sb - VIOLET_THRESHOLD)
        if st is not None:
            votes.append(VIOLET_THRESHOLD - st)
        band = _band_position_vote(rgb, view, cam, T, model)
        if band is not None:
            votes.append(band)
    return float(np.mean(votes)) if votes else 0.0
