"""Which edge points the pose fit uses: balanced subsets of both eyes for its cheap stages,
and the visible arc's two ends when no keypoint gives them."""

from __future__ import annotations

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
    d = np.sum((p[:, None] - p[None]) ** 2, -1)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return p[i], p[j]
