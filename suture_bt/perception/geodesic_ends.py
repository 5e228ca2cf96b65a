"""The visible needle's ends measured along the mask, not across it.

A 125° arc seen obliquely folds into a V or a hook: its two ends may be close in the image
while its bend sticks out, so the mask's farthest pair of pixels (straight-line distance) is
the bend and one end. Distances along the mask (a thin curve) do not have that problem: the
pixel farthest along the mask from any start is an end, and the pixel farthest along the mask
from that end is the other one.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from suture_bt.perception.pose_fit import MaskView

#: 8-neighbour steps (dy, dx) that link each pixel to the ones after it, and their lengths.
_STEPS = ((0, 1), (1, -1), (1, 0), (1, 1))


def _pixel_graph(mask: np.ndarray):
    """Sparse 8-connected graph of the mask's pixels (edge lengths 1 or √2), and their (y, x)."""
    ys, xs = np.nonzero(mask)
    index = np.full(mask.shape, -1, np.int64)
    index[ys, xs] = np.arange(len(ys))
    h, w = mask.shape
    rows, cols, lengths = [], [], []
    for dy, dx in _STEPS:
        y2, x2 = ys + dy, xs + dx
        ok = (y2 >= 0) & (y2 < h) & (x2 >= 0) & (x2 < w)
        j = np.full(len(ys), -1, np.int64)
        j[ok] = index[y2[ok], x2[ok]]
        keep = j >= 0
        rows.append(np.nonzero(keep)[0])
        cols.append(j[keep])
        lengths.append(np.full(int(keep.sum()), np.hypot(dy, dx)))
    r, c, d = (np.concatenate(a) for a in (rows, cols, lengths))
    n = len(ys)
    return coo_matrix((d, (r, c)), shape=(n, n)).tocsr(), ys, xs


def geodesic_ends(view: MaskView) -> tuple[np.ndarray, np.ndarray] | None:
    """The two ends (full-image px, pixel centres) of the mask's largest piece, found by
    distance along the mask; None when that piece has fewer than two pixels."""
    m = view.mask.astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    if n <= 1:
        return None
    piece = lab == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    graph, ys, xs = _pixel_graph(piece)
    if len(ys) < 2:
        return None
    a = int(np.argmax(dijkstra(graph, directed=False, indices=0)))
    b = int(np.argmax(dijkstra(graph, directed=False, indices=a)))
    x0, y0 = view.origin
    return (
        np.array([xs[a] + x0, ys[a] + y0], float),
        np.array([xs[b] + x0, ys[b] + y0], float),
    )
