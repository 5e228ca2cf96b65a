"""Dropping a binary mask's small connected blobs: sensor-noise specks, a few deep pixels
inside the wire, grey specks too small to hide it. Each caller brings its own least area."""

from __future__ import annotations

import cv2
import numpy as np


def without_small_blobs(
    mask: np.ndarray, min_area: float, keep_edge_cut: bool = False
) -> np.ndarray:
    """``mask`` (bool or uint8) as bool without its 8-connected blobs of fewer than
    ``min_area`` pixels; with ``keep_edge_cut``, blobs that reach the array's edge stay
    whatever their size (the edge may have cut a larger one)."""
    _, lab, stats, _ = cv2.connectedComponentsWithStats(
        np.asarray(mask).astype(np.uint8), connectivity=8
    )
    keep = stats[:, cv2.CC_STAT_AREA] >= min_area
    if keep_edge_cut:
        x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
        w, h = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]
        H, W = lab.shape
        keep |= (x == 0) | (y == 0) | (x + w == W) | (y + h == H)
    keep[0] = False
    return keep[lab]
