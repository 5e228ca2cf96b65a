"""Which edge points the pose fit uses: balanced subsets of both eyes for its cheap stages,
and the visible arc's two ends when no keypoint gives them."""

from __future__ import annotations

import cv2
import numpy as np

from suture_bt.perception.mask_view import MaskView, edge_points
from suture_bt.perception.refusal import NeedleNotFound


def subsample(pts: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Up to n of the points, drawn without replacement, in their order."""
    if len(pts) <= n:
        return pts
    return pts[np.sort(rng.choice(len(pts), n, replace=False))]


def balanced(nl: int, nr: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of up to n points from each eye (left first in the ray arrays)."""
    a = np.sort(rng.choice(nl, min(n, nl), replace=False))
    b = nl + np.sort(rng.choice(nr, min(n, nr), replace=False))
    return np.concatenate([a, b])


def mask_ends(view: MaskView, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The mask's two mutually farthest edge points (full-image px): the visible arc's ends."""
    pts = edge_points(view)
    if len(pts) < 2:
        raise NeedleNotFound("the needle mask has no ends (fewer than two edge points)")
    return farthest_pair(pts, np.random.default_rng(seed))


def farthest_pair(pts: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The two mutually farthest edge points: the arc's ends (identity unknown)."""
    p = subsample(pts, 400, rng)
    q = p[_extreme_points(p)]
    d = np.sum((q[:, None] - q[None]) ** 2, -1)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return q[i], q[j]


def _extreme_points(p: np.ndarray) -> np.ndarray:
    """Indices, in order, of the points (N, 2) on their convex hull: the farthest pair is
    among them, and the first of it in row-major order is the all-pairs search's (a few
    dozen of several hundred; that search took 2 ms a call). The hull is exact for the edge
    points' half-pixel grid (doubled to integers); other points are all kept."""
    twice = 2.0 * p
    if len(p) < 3 or not np.array_equal(twice, np.round(twice)) or np.abs(twice).max() > 2**30:
        return np.arange(len(p))
    hull = cv2.convexHull(twice.astype(np.int32), clockwise=False, returnPoints=False)
    return np.sort(hull.reshape(-1))
