"""The wire's apparent thickness in a needle mask: a third, crude depth cue.

Along the wire's ridge (the mask's distance-transform maxima) the distance to the edge is the
wire's half width in pixels, about r·f/z. Its median over the ridge ignores the few ridge
pixels of a blob that is not wire, so it can tell which of two depths a mask agrees with when a
blob of needle colour (a jaw's highlight, seen by one eye) drags the masks' disparity.
"""

from __future__ import annotations

import cv2
import numpy as np

#: A mask's wire thickness agrees with a depth when their ratio is within this factor (either
#: way) of the width a wire there would show: the ridge measure is good to about ±30 %.
WIDTH_AGREEMENT = 0.6
#: The ridge's median distance (L2, 5×5 mask) overestimates a rendered wire's half width by
#: about this much (px): measured 3.0-3.6 px for wires 2.4-3.4 px in half width.
RIDGE_BIAS_PX = 0.4


def ridge_half_width(mask: np.ndarray) -> float | None:
    """Median distance-to-edge (px) over the mask's ridge pixels; None for an empty mask."""
    m = np.asarray(mask, bool).astype(np.uint8)
    if not m.any():
        return None
    dt = cv2.distanceTransform(np.pad(m, 1), cv2.DIST_L2, 5)[1:-1, 1:-1]
    ridge = (dt >= cv2.dilate(dt, np.ones((3, 3), np.uint8))) & (dt > 0)
    return float(np.median(dt[ridge]))


def width_ratio(measured_px: float, wire_radius: float, fx: float, depth: float) -> float:
    """Measured ridge half width over the one a wire at ``depth`` (m) would show."""
    return (measured_px - RIDGE_BIAS_PX) / (wire_radius * fx / depth)


def thin_for(masks, depth: float, not_depth: float, wire_radius: float, fx: float) -> bool:
    """Whether the masks' wire (the thicker eye's ridge width) is as thin as a wire at
    ``depth`` (m) shows and far too thin for one at ``not_depth``."""
    widths = [ridge_half_width(m) for m in masks]
    if not widths or any(w is None for w in widths):
        return False
    at = width_ratio(max(widths), wire_radius, fx, depth)
    not_at = width_ratio(max(widths), wire_radius, fx, not_depth)
    return not_at < WIDTH_AGREEMENT <= at <= 1.0 / WIDTH_AGREEMENT
