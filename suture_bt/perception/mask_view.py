"""A needle mask of one eye (possibly a crop) and its sub-pixel edge points."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MaskView:
    """A needle mask (bool) of one eye, possibly a crop whose top-left pixel is ``origin``.

    ``free_dt`` (optional, a crop at ``free_origin``) holds, for pixels that certainly show
    no needle (tissue or cavity colour, not an occluder), the distance in pixels to the nearest
    pixel that might (0 elsewhere): the model's centre-line is pulled out of free space, which
    pins an arc whose ends are hidden without penalising occluded parts.

    ``occluder`` (optional, same shape as ``mask``) marks pixels of something in front that
    could hide the needle (grey metal that is not needle): where the mask meets it, its
    boundary is where the needle is cut off from view, not the wire's outline, so those edge
    points are left out of the fit.
    """

    mask: np.ndarray
    origin: tuple[int, int] = (0, 0)
    free_dt: np.ndarray | None = None
    free_origin: tuple[int, int] = (0, 0)
    occluder: np.ndarray | None = None


def edge_points(view: MaskView) -> np.ndarray:
    """Sub-pixel edge points (N, 2) in full-image (u, v): midpoints of in/out 4-neighbour pairs
    (pairs touching an ``occluder`` pixel are left out)."""
    m = np.asarray(view.mask, bool)
    x0, y0 = view.origin
    occ = np.zeros_like(m) if view.occluder is None else np.asarray(view.occluder, bool)
    pts = []
    dh = (m[:, 1:] != m[:, :-1]) & ~(occ[:, 1:] | occ[:, :-1])
    v, u = np.nonzero(dh)
    pts.append(np.stack([u + 0.5, v.astype(float)], 1))
    dv = (m[1:, :] != m[:-1, :]) & ~(occ[1:, :] | occ[:-1, :])
    v, u = np.nonzero(dv)
    pts.append(np.stack([u.astype(float), v + 0.5], 1))
    out = np.concatenate(pts, 0)
    return out + np.array([x0, y0], float)
