"""Does the image show the needle where a predicted pose puts a piece of it?

A check for poses the caller already predicts well (an arm that is calibrated and knows its
grasp): sample the predicted centre-line over an arc range, project into both eyes and count
the samples that land on needle-coloured pixels (grey metal, :func:`needle_coloured`) within
``reach_px``. Used to confirm that the tip has emerged past an exit when the localiser cannot
fit the partly buried needle. Samples hidden from view cannot be told from missing ones, so
only a piece that is in front of the tissue should be asked about.
"""

from __future__ import annotations

import cv2
import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.colour_refine import ColourRule, frame_exposure, needle_coloured


def metal_masks(
    images: tuple[np.ndarray, np.ndarray], reach_px: int = 4, rule: ColourRule | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Needle-coloured pixels of each eye, grown by ``reach_px`` (what :func:`arc_hits` reads;
    compute once per frame when asking about many poses). Without a ``rule``, the nominal one
    at the frame's exposure (:meth:`ColourRule.at_exposure`)."""
    rule = rule or ColourRule().at_exposure(frame_exposure(images[0]))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach_px + 1, 2 * reach_px + 1))
    grown = [cv2.dilate(needle_coloured(img, rule).astype(np.uint8), kernel) > 0 for img in images]
    return grown[0], grown[1]


def arc_hits(
    images: tuple[np.ndarray, np.ndarray],
    stereo: StereoCameraModel,
    T_world_needle: np.ndarray,
    needle: NeedleModel,
    angles: np.ndarray,
    reach_px: int = 4,
    rule: ColourRule | None = None,
    masks: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per centre-line sample at ``angles``: seen as metal, per eye (left, right)."""
    masks = masks if masks is not None else metal_masks(images, reach_px, rule)
    pts = needle.point_at(np.asarray(angles, dtype=float))
    world = pts @ np.asarray(T_world_needle)[:3, :3].T + np.asarray(T_world_needle)[:3, 3]
    out = []
    for metal, cam in zip(masks, (stereo.left, stereo.right), strict=True):
        uv = np.rint(cam.project(world)).astype(int)
        h, w = metal.shape
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        hits = np.zeros(len(uv), bool)
        hits[inside] = metal[uv[inside, 1], uv[inside, 0]]
        out.append(hits)
    return out[0], out[1]


def arc_support(
    images: tuple[np.ndarray, np.ndarray],
    stereo: StereoCameraModel,
    T_world_needle: np.ndarray,
    needle: NeedleModel,
    angles: np.ndarray,
    reach_px: int = 4,
    rule: ColourRule | None = None,
) -> tuple[float, float]:
    """Share of the centre-line samples at ``angles`` seen as metal, per eye (left, right)."""
    hits = arc_hits(images, stereo, T_world_needle, needle, angles, reach_px, rule)
    return tuple(float(h.mean()) if len(h) else 0.0 for h in hits)
