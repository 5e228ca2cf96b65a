"""Where points sit relative to the needle's centre-line arc: the offset to its nearest point,
the place along its circle, and where the arc crosses a plane. The task priors
(:mod:`needle_prior`) and their soft term (:mod:`prior_term`) measure their misses with these;
the fit asks them of small batches many times, so the per-pose loops are compiled."""

from __future__ import annotations

import functools
import math

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.perception.compiled import kernel


def arc_offsets(T: np.ndarray, points: np.ndarray, model: NeedleModel) -> np.ndarray:
    """Vectors (K, P, 3), in the poses' frame, from each point (P, 3) to the nearest point of
    the needle's centre-line arc at each pose (K, 4, 4): on the circle within the arc's span,
    else the nearer end (the distance grows with the angle past either end). Compiled: the
    fit asks this of small batches many times (as numpy calls, 5 ms of a call with priors)."""
    T = np.ascontiguousarray(np.reshape(T, (-1, 4, 4)), dtype=np.float64)
    points = np.ascontiguousarray(np.reshape(points, (-1, 3)), dtype=np.float64)
    return _arc_offsets(T, points, model.radius, model.tip_angle, model.base_angle, _ends(model))


@functools.lru_cache(maxsize=8)
def _ends(model: NeedleModel) -> np.ndarray:
    """Tip and base (2, 3) in the needle frame (read-only: shared by every call)."""
    ends = np.stack([model.tip, model.base]).astype(np.float64)
    ends.flags.writeable = False
    return ends


@kernel()
def _arc_offsets(T, points, radius, tip_angle, base_angle, ends):
    """:func:`arc_offsets` per pose and point in one loop (``ends`` = tip, base in the
    needle frame)."""
    K, P = T.shape[0], points.shape[0]
    out = np.empty((K, P, 3))
    for k in range(K):
        for q in range(P):
            d0 = points[q, 0] - T[k, 0, 3]
            d1 = points[q, 1] - T[k, 1, 3]
            d2 = points[q, 2] - T[k, 2, 3]
            # the point in the needle frame: Rᵀ (point - t)
            p0 = T[k, 0, 0] * d0 + T[k, 1, 0] * d1 + T[k, 2, 0] * d2
            p1 = T[k, 0, 1] * d0 + T[k, 1, 1] * d1 + T[k, 2, 1] * d2
            p2 = T[k, 0, 2] * d0 + T[k, 1, 2] * d1 + T[k, 2, 2] * d2
            theta = math.atan2(p1, p0)
            if tip_angle <= theta <= base_angle:
                n0, n1, n2 = radius * math.cos(theta), radius * math.sin(theta), 0.0
            else:
                e = 0
                t0, t1, t2 = p0 - ends[0, 0], p1 - ends[0, 1], p2 - ends[0, 2]
                b0, b1, b2 = p0 - ends[1, 0], p1 - ends[1, 1], p2 - ends[1, 2]
                dt = t0 * t0 + t1 * t1 + t2 * t2  # products, not ** 2: see compiled.py
                db = b0 * b0 + b1 * b1 + b2 * b2
                if db < dt:
                    e = 1
                n0, n1, n2 = ends[e, 0], ends[e, 1], ends[e, 2]
            v0, v1, v2 = n0 - p0, n1 - p1, n2 - p2
            for i in range(3):
                out[k, q, i] = T[k, i, 0] * v0 + T[k, i, 1] * v1 + T[k, i, 2] * v2
    return out


def arc_distance(point_world: np.ndarray, T_world_needle: np.ndarray, model: NeedleModel) -> float:
    """Distance (m) from a world point to the needle's centre-line arc at a pose (exact)."""
    point = np.asarray(point_world, float)[None]
    return float(np.linalg.norm(arc_offsets(np.asarray(T_world_needle)[None], point, model)))


def place_offsets(
    T: np.ndarray, point: np.ndarray, arc_angle: float, model: NeedleModel, signed: bool = False
) -> np.ndarray:
    """Signed angles (K,) by which ``point`` sits on each pose's circle (K, 4, 4; point in
    the poses' frame) past the arc angle ``arc_angle``: from that place, or, unless
    ``signed``, from its base ↔ tip swap's when that is nearer."""
    places = (arc_angle,) if signed else (arc_angle, model.swapped_angle(arc_angle))
    return _place_offsets(
        np.ascontiguousarray(T, dtype=np.float64),
        np.asarray(point, dtype=np.float64),
        np.array(places, dtype=np.float64),
    )


@kernel()
def _place_offsets(T, point, places):
    """:func:`place_offsets` compiled (the fit calls it on small batches many times)."""
    K = T.shape[0]
    out = np.empty(K)
    for k in range(K):
        x = y = 0.0
        for m in range(3):
            x += T[k, m, 0] * (point[m] - T[k, m, 3])
            y += T[k, m, 1] * (point[m] - T[k, m, 3])
        theta = math.atan2(y, x)
        best = np.inf
        for a in places:
            d = (theta - a + math.pi) % (2 * math.pi) - math.pi
            if abs(d) < abs(best):
                best = d
        out[k] = best
    return out


def plane_crossings(
    T_world_needle: np.ndarray, model: NeedleModel, point: np.ndarray, normal: np.ndarray
) -> np.ndarray:
    """World points (N×3) where the needle's centre-line crosses the plane through ``point``
    with ``normal`` (linear between 1° samples of the arc: ≤ 2 µm off the circle)."""
    n = max(int(np.degrees(model.arc_angle)), 2)
    local = model.point_at(np.linspace(model.base_angle, model.tip_angle, n))
    world = local @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
    h = (world - np.asarray(point, float)) @ np.asarray(normal, float)
    k = np.nonzero(np.sign(h[:-1]) * np.sign(h[1:]) < 0)[0]
    w = h[k] / (h[k] - h[k + 1])
    return world[k] + w[:, None] * (world[k + 1] - world[k])
