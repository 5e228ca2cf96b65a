"""Where the tissue cuts a needle in a port: the arc's spans below the ports' surfaces.

The mask of a needle in a port stops where the wire enters the tissue. The fit's edge model
is the whole arc, whose rounded ends sit at the needle's base and tip; the outline's end at
the port is then explained only by a pose whose own end sits there, slid along its circle out
of the tissue (development in-port scenes: the true pose cost 1.3× such a slide, and a grasp's
held place then refused every pose the fit found). A caller that says the needle is in a port
(a port prior with its surface normal) says where the tissue is: the part of the arc below
every given port's surface plane is hidden, and the seen wire ends at the plane. The edge
residuals take the nearest seen point of the arc: a ray whose nearest arc point is hidden
measures to the cut, a rounded end set back by the wire's radius so that it reaches the plane.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from suture_bt.geometry import NeedleModel

#: Samples of the arc angle over which hidden spans are found (their ends are then exact).
N_CUT_SAMPLES = 24
#: Hidden spans kept per pose (a needle in one port hides one end, in an entry and its exit
#: its middle; one dipping into the tissue and out again through the same plane both ends).
MAX_SPANS = 2


@dataclass(frozen=True)
class TissueCut:
    """Port surface planes in the left-camera frame: points (Q, 3) and outward normals (Q, 3),
    for a needle ``model``. A point of the arc is hidden when it lies below every plane."""

    points: np.ndarray
    normals: np.ndarray
    model: NeedleModel

    @classmethod
    def from_ports(cls, ports, T_cam_world: np.ndarray, model: NeedleModel) -> TissueCut | None:
        """The cut of ports given as (world point, world outward normal) pairs (None: none)."""
        if not ports:
            return None
        R, t = T_cam_world[:3, :3], T_cam_world[:3, 3]
        P = np.array([R @ np.asarray(p, float) + t for p, _ in ports])
        N = np.array([R @ np.asarray(n, float) for _, n in ports])
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        return cls(np.ascontiguousarray(P), np.ascontiguousarray(N), model)

    def __post_init__(self) -> None:
        m = self.model
        grid = np.linspace(m.tip_angle, m.base_angle, N_CUT_SAMPLES)
        shift = m.wire_radius / m.radius
        object.__setattr__(self, "_args", (m.radius, m.tip_angle, m.base_angle, shift, grid))

    def spans(self, T: np.ndarray) -> np.ndarray:
        """Hidden spans (K, MAX_SPANS, 2) of arc angle per pose (K, 4, 4; NaN rows: none),
        each end that meets the seen arc set back by the wire's radius."""
        T = np.ascontiguousarray(np.asarray(T, dtype=np.float64).reshape(-1, 4, 4))
        return hidden_spans(T, self.points, self.normals, *self._args)

    def spans_and_derivatives(self, T: np.ndarray, T6: np.ndarray, steps) -> tuple:
        """The spans at T (K, 4, 4) and their forward differences (K, 6, MAX_SPANS, 2) in the
        six parameters, from the poses T6 (K, 6, 4, 4) stepped by ``steps`` (0 where a span
        appears or goes)."""
        K = len(T)
        both = self.spans(np.concatenate([np.reshape(T, (K, 4, 4)), T6.reshape(-1, 4, 4)]))
        s0, s6 = both[:K], both[K:].reshape(K, 6, MAX_SPANS, 2)
        d = (s6 - s0[:, None]) / np.asarray(steps, float)[None, :, None, None]
        return s0, np.where(np.isfinite(d), d, 0.0)


@njit(cache=True)
def _root(A, B, C, u, v):
    """The angle in [u, v] where A cos θ + B sin θ + C = 0 (NaN: none)."""
    rho = math.hypot(A, B)
    if rho < 1e-15 or abs(C) > rho:
        return np.nan
    phi, alpha = math.atan2(B, A), math.acos(-C / rho)
    for sgn in (1.0, -1.0):
        th = phi + sgn * alpha
        th += 2 * math.pi * math.floor((u - th) / (2 * math.pi) + 1.0)  # first ≥ u
        if th - 2 * math.pi >= u - 1e-12:
            th -= 2 * math.pi
        if th <= v + 1e-12:
            return min(max(th, u), v)
    return np.nan


@njit(cache=True)
def _boundary(A, B, C, u, v):
    """Where 'below every plane' changes within [u, v]: among the planes' roots there, the one
    where the highest plane height is nearest zero."""
    best, arg = np.inf, 0.5 * (u + v)
    for q in range(A.shape[0]):
        th = _root(A[q], B[q], C[q], u, v)
        if not math.isfinite(th):
            continue
        c, s = math.cos(th), math.sin(th)
        g = -np.inf
        for p in range(A.shape[0]):
            g = max(g, A[p] * c + B[p] * s + C[p])
        if abs(g) < best:
            best, arg = abs(g), th
    return arg


@njit(cache=True)
def hidden_spans(T, P, N, rad, lo, hi, shift, grid):
    """Spans (K, 2, 2) of arc angle below every plane (points P, normals N; Q each) for poses
    T (K, 4, 4): found on ``grid`` (angles lo..hi), their ends solved exactly, those meeting
    the seen arc set back by ``shift`` (rad) into it. NaN rows: no span."""
    K, Q, S = T.shape[0], P.shape[0], grid.shape[0]
    out = np.full((K, 2, 2), np.nan)
    A, B, C = np.empty(Q), np.empty(Q), np.empty(Q)
    gc, gs = np.cos(grid), np.sin(grid)
    for k in range(K):
        for q in range(Q):
            a = b = c = 0.0
            for m in range(3):
                a += N[q, m] * T[k, m, 0]
                b += N[q, m] * T[k, m, 1]
                c += N[q, m] * (T[k, m, 3] - P[q, m])
            A[q], B[q], C[q] = rad * a, rad * b, c
        n, prev, start = 0, False, lo
        for i in range(S):
            hid = True
            for q in range(Q):
                if A[q] * gc[i] + B[q] * gs[i] + C[q] >= 0.0:
                    hid = False
                    break
            if hid and not prev:
                start = lo if i == 0 else _boundary(A, B, C, grid[i - 1], grid[i])
            if prev and not hid and n < 2:
                out[k, n, 0] = start
                out[k, n, 1] = _boundary(A, B, C, grid[i - 1], grid[i])
                n += 1
            prev = hid
        if prev and n < 2:
            out[k, n, 0], out[k, n, 1] = start, hi
            n += 1
        for j in range(n):  # the cut's rounded end reaches the plane
            if out[k, j, 0] > lo:
                out[k, j, 0] = max(out[k, j, 0] - shift, lo)
            if out[k, j, 1] < hi:
                out[k, j, 1] = min(out[k, j, 1] + shift, hi)
    return out


@njit(cache=True)
def clamp_to_seen(th, spans, lo, hi):
    """The arc angle ``th`` moved out of a hidden span (2, 2) to its nearer end that meets
    the seen arc; (angle, span index, end index) with -1 when it was not hidden."""
    for j in range(spans.shape[0]):
        a, b = spans[j, 0], spans[j, 1]
        if a < th < b:
            if a <= lo:
                return b, j, 1
            if b >= hi:
                return a, j, 0
            return (a, j, 0) if th - a < b - th else (b, j, 1)
    return th, -1, -1


@njit(cache=True)
def clamp_all(theta, spans, lo, hi):
    """:func:`clamp_to_seen` over angles (K, N) with each pose's spans (K, 2, 2)."""
    out = theta.copy()
    for k in range(theta.shape[0]):
        for n in range(theta.shape[1]):
            out[k, n] = clamp_to_seen(theta[k, n], spans[k], lo, hi)[0]
    return out
