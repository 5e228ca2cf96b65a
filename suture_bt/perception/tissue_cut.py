"""Where the tissue cuts a needle: the arc's spans inside the tissue, which the image cannot show.

The mask of a needle in a port stops where the wire enters the tissue. The fit's edge model
is the whole arc, whose rounded ends sit at the needle's base and tip; the outline's end at
the port is then explained only by a pose whose own end sits there, slid along its circle out
of the tissue (development in-port scenes: the true pose cost 1.3× such a slide, and a grasp's
held place then refused every pose the fit found). Whoever knows where the tissue is says so:
a caller that says the needle is in a port (a port prior with its surface normal: the space
below every given port's surface plane), and the task's known phantom (its solid as convex
pieces, :func:`~suture_bt.geometry.tissue_surface.solid_pieces`). The part of the arc inside
any piece is hidden, and the seen wire ends at the surface. The edge residuals take the
nearest seen point of the arc: a ray whose nearest arc point is hidden measures to the cut, a
rounded end placed where the mask's wire ends: at a steep entry set back by the wire's radius
so that it reaches the surface; at a shallow one past it, where the wire's tapering top goes
under (:func:`_entry_setback`). A piece may ask that
the arc reach some depth into it before it hides anything (the phantom's solid does: a pose
that only dips under the surface would otherwise hide what a needle lying on it shows).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import prange

from suture_bt.geometry import NeedleModel
from suture_bt.perception.compiled import kernel

#: Samples of the arc angle over which hidden spans are found (their ends are then exact).
N_CUT_SAMPLES = 24
#: Hidden spans kept per pose (a needle in one port hides one end, in an entry and its exit
#: its middle; one dipping into the tissue and out again through the same plane both ends).
MAX_SPANS = 2
#: The largest cot φ of a wire entering the tissue at angle φ that sets its cut's end back
#: (18°: a shallower entry counts as 18°).
MAX_ENTRY_COT = 3.0
#: How much (in wire radii) of the tapering top of a wire entering the tissue its mask loses.
#: True masks: the true pose's edge cost is least with the cap set back to the plane (0.8-1.2
#: r) at twelve development in-port scenes (entries 66-72°, cot φ 0.33-0.44) and 0.5 r past
#: it at a held needle's tip dipping into the held-out phantom at 27° (36796497 ``held_start``
#: #29, cot φ 1.96): the cap's tip 0.36-0.46 r short of the taper's.
ENTRY_TAPER_LOST = 0.4
#: Fixed-point steps from a set-back span end back to its plane root (its derivative's point).
ROOT_ITERATIONS = 4


@dataclass(frozen=True)
class TissueCut:
    """The tissue as a union of convex pieces, each the space below all of its planes, in the
    left-camera frame: plane points (Q, 3), outward normals (Q, 3) and ``groups`` (G + 1
    offsets: piece g owns planes groups[g]:groups[g + 1]; None: one piece of every plane),
    for a needle ``model``. A point of the arc is hidden when it lies inside any piece, along
    a stretch of arc that reaches ``depths[g]`` (m; None: 0) inside some piece g."""

    points: np.ndarray
    normals: np.ndarray
    model: NeedleModel
    groups: np.ndarray | None = None
    depths: np.ndarray | None = None

    @classmethod
    def from_ports(cls, ports, T_cam_world: np.ndarray, model: NeedleModel) -> TissueCut | None:
        """The cut of ports given as (world point, world outward normal) pairs (None: none):
        one piece, below every port's surface plane."""
        if not ports:
            return None
        return cls.from_pieces([ports], T_cam_world, model)

    @classmethod
    def from_pieces(
        cls, pieces, T_cam_world: np.ndarray, model: NeedleModel, depths=None
    ) -> TissueCut | None:
        """The cut of convex pieces, each a list of (world point, world outward normal) planes,
        and how deep (m) the arc must reach into each to be hidden there (None: no piece
        with a plane)."""
        depths = [0.0] * len(pieces) if depths is None else list(depths)
        kept = [k for k, p in enumerate(pieces) if len(p)]
        pieces, depths = [list(pieces[k]) for k in kept], [depths[k] for k in kept]
        if not pieces:
            return None
        R, t = T_cam_world[:3, :3], T_cam_world[:3, 3]
        planes = [pl for piece in pieces for pl in piece]
        P = np.array([R @ np.asarray(p, float) + t for p, _ in planes])
        N = np.array([R @ np.asarray(n, float) for _, n in planes])
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        groups = np.cumsum([0] + [len(p) for p in pieces]).astype(np.int64)
        return cls(
            np.ascontiguousarray(P), np.ascontiguousarray(N), model, groups, np.array(depths)
        )

    def __post_init__(self) -> None:
        m = self.model
        grid = np.linspace(m.tip_angle, m.base_angle, N_CUT_SAMPLES)
        shift = m.wire_radius / m.radius
        groups = self.groups
        if groups is None:
            groups = np.array([0, len(self.points)], np.int64)
        groups = np.ascontiguousarray(groups, dtype=np.int64)
        depths = np.zeros(len(groups) - 1) if self.depths is None else self.depths
        depths = np.ascontiguousarray(depths, dtype=np.float64)
        object.__setattr__(self, "groups", groups)
        object.__setattr__(self, "depths", depths)
        args = (groups, depths, m.radius, m.tip_angle, m.base_angle, shift, grid)
        object.__setattr__(self, "_args", args)
        object.__setattr__(self, "_shift", shift)

    def spans(self, T: np.ndarray) -> np.ndarray:
        """Hidden spans (K, MAX_SPANS, 2) of arc angle per pose (K, 4, 4; NaN rows: none),
        each end that meets the seen arc set back from the plane (:func:`_entry_setback`)."""
        T = np.ascontiguousarray(np.asarray(T, dtype=np.float64).reshape(-1, 4, 4))
        return hidden_spans(T, self.points, self.normals, *self._args)[0]

    def spans_and_derivatives(self, T: np.ndarray, T6: np.ndarray, steps) -> tuple:
        """The spans at T (K, 4, 4) and their derivatives (K, 6, MAX_SPANS, 2) in the six
        parameters, from the poses T6 (K, 6, 4, 4) stepped by ``steps``: each end's plane
        root differentiated along the pose's forward differences (:func:`span_derivatives`;
        0 for an end of the arc). Only the poses with a span at T are differentiated (most
        poses have none)."""
        T = np.ascontiguousarray(np.asarray(T, dtype=np.float64).reshape(-1, 4, 4))
        K = len(T)
        s0, planes = hidden_spans(T, self.points, self.normals, *self._args)
        d = np.zeros((K, 6, MAX_SPANS, 2))
        cut = np.isfinite(s0).any(axis=(1, 2))
        if cut.any():
            T6c = np.reshape(T6, (K, 6, 4, 4))[cut]
            dT = (T6c - T[cut][:, None]) / np.asarray(steps, float)[None, :, None, None]
            d[cut] = span_derivatives(
                s0[cut], planes[cut], T[cut], dT, self.normals, self.model.radius, self._shift
            )
        return s0, d


@kernel()
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


@kernel()
def _sample(A, B, C, G, act, D, c, s):
    """The arc point at (cos, sin) = (c, s) against the pieces (plane offsets G) the circle
    reaches (``act``): how far outside the tissue it is (the least of each piece's highest
    plane height; < 0: hidden), and whether it is at least D[g] inside some piece g."""
    out, deep = np.inf, False
    for g in range(G.shape[0] - 1):
        if not act[g]:
            continue
        top = -np.inf
        for p in range(G[g], G[g + 1]):
            top = max(top, A[p] * c + B[p] * s + C[p])
        out = min(out, top)
        deep = deep or (top < 0.0 and top <= -D[g])
    return out, deep


@kernel()
def _boundary(A, B, C, G, act, D, u, v):
    """Where 'inside a piece' changes within [u, v]: among the roots there of the planes of
    the pieces the circle reaches, the one where the tissue height (:func:`_sample`) is
    nearest zero; and that plane (-1: none, the span's middle)."""
    best, arg, plane = np.inf, 0.5 * (u + v), -1
    for g in range(G.shape[0] - 1):
        if not act[g]:
            continue
        for q in range(G[g], G[g + 1]):
            th = _root(A[q], B[q], C[q], u, v)
            if not math.isfinite(th):
                continue
            h = _sample(A, B, C, G, act, D, math.cos(th), math.sin(th))[0]
            if abs(h) < best:
                best, arg, plane = abs(h), th, q
    return arg, plane


@kernel(inline="always")
def spans_of_pose(k, T, P, N, G, D, rad, lo, hi, shift, grid, gc, gs, out, planes):
    """:func:`hidden_spans` for pose k alone, written into row k of ``out`` (NaN on entry)
    and ``planes`` (-1 on entry); ``gc``, ``gs``: the grid's cosines and sines. The compiled
    LM trial calls it pose by pose (:mod:`lm_step`), with the same bits."""
    Q, S, NG = P.shape[0], grid.shape[0], G.shape[0] - 1
    A, B, C = np.empty(Q), np.empty(Q), np.empty(Q)
    act = np.empty(NG, np.bool_)
    for q in range(Q):
        a = b = c = 0.0
        for m in range(3):
            a += N[q, m] * T[k, m, 0]
            b += N[q, m] * T[k, m, 1]
            c += N[q, m] * (T[k, m, 3] - P[q, m])
        A[q], B[q], C[q] = rad * a, rad * b, c
    any_act = False
    for g in range(NG):
        act[g] = True
        for q in range(G[g], G[g + 1]):
            if C[q] - math.hypot(A[q], B[q]) >= 0.0:
                act[g] = False
                break
        any_act = any_act or act[g]
    if not any_act:
        return
    n, prev, start, start_plane, deep = 0, False, lo, -1, False
    for i in range(S):
        h, deep_here = _sample(A, B, C, G, act, D, gc[i], gs[i])
        hid = h < 0.0
        if hid and not prev:
            start, start_plane = lo, -1
            if i > 0:
                start, start_plane = _boundary(A, B, C, G, act, D, grid[i - 1], grid[i])
            deep = False
        if hid:
            deep = deep or deep_here
        if prev and not hid and n < 2 and deep:
            out[k, n, 0], planes[k, n, 0] = start, start_plane
            out[k, n, 1], planes[k, n, 1] = _boundary(A, B, C, G, act, D, grid[i - 1], grid[i])
            n += 1
        prev = hid
    if prev and n < 2 and deep:
        out[k, n, 0], out[k, n, 1] = start, hi
        planes[k, n, 0] = start_plane
        n += 1
    kept = 0
    for j in range(n):  # the cut's rounded end reaches as far as the wire's top is seen
        a, b = out[k, j, 0], out[k, j, 1]
        pa, pb = planes[k, j, 0], planes[k, j, 1]
        if a > lo:
            a = max(a - _setback(A, B, pa, a, rad, shift), lo)
        if b < hi:
            b = min(b + _setback(A, B, pb, b, rad, shift), hi)
        if a >= b:  # a shallow dip: the wire's top stays above the surface
            continue
        out[k, kept, 0], out[k, kept, 1] = a, b
        planes[k, kept, 0], planes[k, kept, 1] = pa, pb
        for e in range(2):  # an end clamped to the arc's end no longer moves
            if out[k, kept, e] <= lo or out[k, kept, e] >= hi:
                planes[k, kept, e] = -1
        kept += 1
    for j in range(kept, n):
        out[k, j, 0] = out[k, j, 1] = np.nan
        planes[k, j, 0] = planes[k, j, 1] = -1


@kernel()
def _entry_setback(a, b, th, rad, shift):
    """How far (rad) a span's end at arc angle ``th`` on a plane (``a cos θ + b sin θ + c``
    its height along the arc) is set back into the seen arc, where the model's rounded end
    (``shift`` long) is to end: a wire of radius r meeting the plane at angle φ shows its top
    r·cot φ past where its centre-line crosses, tapering to nothing, and the mask keeps all
    but the last :data:`ENTRY_TAPER_LOST` r of it. A steep entry (cot φ ≤ 0.4) sets the cap
    back to the plane (``shift``), a shallow one reaches past it; cot φ at most
    :data:`MAX_ENTRY_COT`."""
    sin_phi = min(abs(b * math.cos(th) - a * math.sin(th)) / rad, 1.0)
    cos_phi = math.sqrt(1.0 - sin_phi * sin_phi)
    cot = MAX_ENTRY_COT if cos_phi >= MAX_ENTRY_COT * sin_phi else cos_phi / sin_phi
    return shift * min(1.0, 1.0 + ENTRY_TAPER_LOST - cot)


@kernel()
def _setback(A, B, q, th, rad, shift):
    """:func:`_entry_setback` of an end on plane ``q``; ``shift`` for an end on none (-1)."""
    if q < 0:
        return shift
    return _entry_setback(A[q], B[q], th, rad, shift)


@kernel()
def spans_of_poses(k0, k1, T, P, N, G, D, rad, lo, hi, shift, grid, gc, gs, out, planes):
    """:func:`spans_of_pose` for poses k0..k1-1 on the calling thread (a loop, as
    :func:`hidden_spans` runs it: inlined alone elsewhere the compiled code differs in the
    last bit)."""
    for k in range(k0, k1):
        spans_of_pose(k, T, P, N, G, D, rad, lo, hi, shift, grid, gc, gs, out, planes)


@kernel(parallel=True)
def grid_circle(grid):
    """Cosines and sines of the span search's grid angles, computed once for the compiled
    LM trial, in a parallel function as :func:`hidden_spans` computes them."""
    return np.cos(grid), np.sin(grid)


@kernel(parallel=True)
def hidden_spans(T, P, N, G, D, rad, lo, hi, shift, grid):
    """Spans (K, 2, 2) of arc angle inside the tissue (planes: points P, normals N; Q each;
    pieces: plane offsets G, depths D) for poses T (K, 4, 4): found on ``grid`` (angles
    lo..hi), kept where a sample reaches a piece's depth, their ends solved exactly, those
    meeting the seen arc set back into it (:func:`_entry_setback`, a steep entry by ``shift``
    rad). NaN rows: no span. A piece
    with a plane the pose's whole circle lies outside of is skipped (most poses: all).
    Also the plane each end lies on (K, 2, 2; -1: an end of the arc, which does not move)."""
    K = T.shape[0]
    out = np.full((K, 2, 2), np.nan)
    planes = np.full((K, 2, 2), -1, np.int64)
    gc, gs = grid_circle(grid)
    for k in prange(K):  # poses are independent: the same bits on any number of threads
        spans_of_pose(k, T, P, N, G, D, rad, lo, hi, shift, grid, gc, gs, out, planes)
    return out, planes


@kernel()
def span_derivatives(spans, planes, T, dT, N, rad, shift):
    """d(span ends)/d(parameter) (K, 6, 2, 2) from the poses' derivatives dT (K, 6, 4, 4):
    an end on plane q lies at a root θ of A cos θ + B sin θ + C = 0 (A, B, C linear in the
    pose), so dθ = -(dA cos θ + dB sin θ + dC) / (B cos θ - A sin θ), set back from it by
    :func:`_entry_setback` (which moves with θ and with the plane's angle to the arc); an end
    of the arc does not move (0), nor does one where the root is tangent (0: it appears or
    goes there)."""
    K = spans.shape[0]
    out = np.zeros((K, 6, 2, 2))
    for k in range(K):
        for j in range(2):
            for e in range(2):
                q = planes[k, j, e]
                if q < 0:
                    continue
                a = b = 0.0
                for m in range(3):
                    a += N[q, m] * T[k, m, 0]
                    b += N[q, m] * T[k, m, 1]
                sign = -1.0 if e == 0 else 1.0  # start = root - setback, end = root + setback
                th = spans[k, j, e]  # back to the root the end was set back from
                for _ in range(ROOT_ITERATIONS):
                    th = spans[k, j, e] - sign * _entry_setback(rad * a, rad * b, th, rad, shift)
                c, s = math.cos(th), math.sin(th)
                g = b * c - a * s  # sin of the entry angle, signed
                den = rad * g
                if abs(den) < 1e-12:
                    continue
                # d(setback)/dg: 0 where cot φ or the setback is clamped
                ag = min(abs(g), 1.0)
                dsb_dg = 0.0
                cot = math.sqrt(1.0 - ag * ag) / ag if ag > 0.0 else np.inf
                if ENTRY_TAPER_LOST < cot < MAX_ENTRY_COT and ag < 1.0:
                    dcot = -1.0 / (ag * ag * math.sqrt(1.0 - ag * ag))
                    dsb_dg = -shift * dcot * (1.0 if g > 0 else -1.0)
                dg_dth = -b * s - a * c
                for i in range(6):
                    da = db = dc = 0.0
                    for m in range(3):
                        da += N[q, m] * dT[k, i, m, 0]
                        db += N[q, m] * dT[k, i, m, 1]
                        dc += N[q, m] * dT[k, i, m, 3]
                    dth = -(rad * (da * c + db * s) + dc) / den
                    dg = db * c - da * s + dg_dth * dth
                    out[k, i, j, e] = dth + sign * dsb_dg * dg
    return out


@kernel()
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


@kernel()
def clamp_all(theta, spans, lo, hi):
    """:func:`clamp_to_seen` over angles (K, N) with each pose's spans (K, 2, 2)."""
    out = theta.copy()
    for k in range(theta.shape[0]):
        for n in range(theta.shape[1]):
            out[k, n] = clamp_to_seen(theta[k, n], spans[k], lo, hi)[0]
    return out
