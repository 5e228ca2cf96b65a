"""Compiled inner loop of the pose fit: edge residuals and their weighted normal equations.

The same arithmetic as :mod:`edge_residuals` (nearest arc angle by a grid and Newton steps,
the tube residual in pixels, its analytic Jacobian), fused per pose and edge ray in one
numba loop, and summed straight into the Levenberg-Marquardt normal equations JᵀWJ and JᵀWr
of the robust loss. In numpy each of these steps is a call on small arrays whose overhead
dominates (about 1 ms per iteration of a batch); here an iteration costs what its arithmetic
does. Results agree with the numpy functions to rounding (tests/test_edge_kernel.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from suture_bt.geometry import NeedleModel
from suture_bt.perception.compiled import kernel
from suture_bt.perception.edge_residuals import N_THETA_GRID, EdgeRays
from suture_bt.perception.tissue_cut import clamp_to_seen

_LOSS_CODES = {"cauchy": 0, "geman_mcclure": 1}
#: Floating-point licences of the compiled loop: fused multiply-adds, reciprocals, the sign
#: of zero; never "no NaN or infinity" (undefined residuals are NaN and tested as such), nor
#: reordered sums or approximate library functions (with those, one ray in 5,543 of the
#: tissue-cut test found another nearest arc angle). About 20 % faster (on in-port views'
#: calls: 67 → 54 ns per pose and ray); results move at the rounding level.
FAST_MATH = {"contract", "arcp", "nsz"}


@kernel(fastmath=FAST_MATH)
def _turned(c, s, delta):
    """cos and sin of θ - delta from those of θ (series for the small steps of the search:
    exact to rounding for |delta| ≤ 0.25, the library's cos and sin beyond)."""
    if abs(delta) > 0.25:
        cd, sd = math.cos(delta), math.sin(delta)
    else:
        d2 = delta * delta
        cd = 1.0 - d2 / 2 * (1.0 - d2 / 12 * (1.0 - d2 / 30 * (1.0 - d2 / 56 * (1.0 - d2 / 90))))
        sd = delta * (1.0 - d2 / 6 * (1.0 - d2 / 20 * (1.0 - d2 / 42 * (1.0 - d2 / 72))))
    return c * cd + s * sd, s * cd - c * sd


@kernel(fastmath=FAST_MATH)
def _nearest_angle(o0, o1, o2, d0, d1, d2, rad, lo, hi, gv, gc, gs, start, c, s):
    """:func:`edge_residuals.nearest_arc_angle` for one ray, with its cosine and sine: a grid
    search over the angles ``gv`` (cosines ``gc``, sines ``gs``) unless ``start`` ≥ lo - 1
    (its cosine ``c`` and sine ``s``), then two Newton steps."""
    od = o0 * d0 + o1 * d1 + o2 * d2
    grid = gv.shape[0]
    theta = start
    if start < lo - 1.0:
        best = np.inf
        for i in range(grid):
            q = rad * (d0 * gc[i] + d1 * gs[i]) - od
            m = -2.0 * rad * (o0 * gc[i] + o1 * gs[i]) - q * q
            if m < best:
                best, theta, c, s = m, gv[i], gc[i], gs[i]
    clip = (hi - lo) / grid
    for _ in range(2):
        u = c * d0 + s * d1
        v = c * d1 - s * d0
        qd = rad * u - od
        num = o0 * s - o1 * c - qd * v
        den = o0 * c + o1 * s - rad * v * v + qd * u
        step = num / den if den > 0 else 0.0
        step = min(max(step, -clip), clip)
        new = min(max(theta - step, lo), hi)
        c, s = _turned(c, s, theta - new)
        theta = new
    return theta, c, s


@kernel(fastmath=FAST_MATH)
def _irls(r, sigma, loss):
    u = r / sigma
    q = 1.0 + u * u  # not u ** 2: see compiled.py
    return 1.0 / q if loss == 0 else 1.0 / (q * q)


@kernel(parallel=True, fastmath=FAST_MATH)
def angle_grid(lo, hi, grid):
    """The nearest-angle search's grid: ``grid`` angles lo..hi with their cosines and sines,
    compiled as :func:`edge_system` computed them, in a parallel function with its licences
    (compiled without them, the same grid came out with other last bits, which moves the
    nearest angles' Newton steps)."""
    gv = np.linspace(lo, hi, grid)
    return gv, np.cos(gv), np.sin(gv)


@kernel(fastmath=FAST_MATH)
def edge_pose(
    k, T, T6, steps, origins, dirs, dz, focal, rad, wire, lo, hi, gv, gc, gs, theta_start,
    cs_start, sigma, loss, want_system, seeded, cut, spans, dspans, r, theta, cs, A, g,
):  # fmt: skip
    """:func:`edge_system` for pose k alone, written into row k of r, θ, cos and sin, A and
    g (r NaN and A, g zero on entry); ``gv``, ``gc``, ``gs``: the grid's angles, cosines and
    sines; ``seeded`` and ``cut``: whether ``theta_start`` and ``spans`` hold row k. The
    compiled LM trial calls it pose by pose (:mod:`lm_step`), with the same bits."""
    N = origins.shape[0]
    M = np.empty((6, 3, 2))
    b = np.empty((6, 3))
    J = np.empty(6)
    R = T[k, :3, :3]
    p = T[k, :3, 3]
    if not np.all(np.isfinite(T[k])):
        for n in range(N):
            theta[k, n], cs[0, k, n], cs[1, k, n] = lo, math.cos(lo), math.sin(lo)
        return
    if want_system:
        # Per parameter: Rᵀ dR (first two columns) and Rᵀ dp.
        for j in range(6):
            for i in range(3):
                for c in range(2):
                    acc = 0.0
                    for m in range(3):
                        acc += R[m, i] * (T6[k, j, m, c] - T[k, m, c]) / steps[j]
                    M[j, i, c] = acc
                acc = 0.0
                for m in range(3):
                    acc += R[m, i] * (T6[k, j, m, 3] - T[k, m, 3]) / steps[j]
                b[j, i] = acc
    for n in range(N):
        x0 = origins[n, 0] - p[0]
        x1 = origins[n, 1] - p[1]
        x2 = origins[n, 2] - p[2]
        o0 = R[0, 0] * x0 + R[1, 0] * x1 + R[2, 0] * x2
        o1 = R[0, 1] * x0 + R[1, 1] * x1 + R[2, 1] * x2
        o2 = R[0, 2] * x0 + R[1, 2] * x1 + R[2, 2] * x2
        d0 = R[0, 0] * dirs[n, 0] + R[1, 0] * dirs[n, 1] + R[2, 0] * dirs[n, 2]
        d1 = R[0, 1] * dirs[n, 0] + R[1, 1] * dirs[n, 1] + R[2, 1] * dirs[n, 2]
        d2 = R[0, 2] * dirs[n, 0] + R[1, 2] * dirs[n, 1] + R[2, 2] * dirs[n, 2]
        if seeded:
            th, c, s = _nearest_angle(
                o0, o1, o2, d0, d1, d2, rad, lo, hi, gv, gc, gs,
                theta_start[k, n], cs_start[0, k, n], cs_start[1, k, n],
            )  # fmt: skip
        else:
            th, c, s = _nearest_angle(
                o0, o1, o2, d0, d1, d2, rad, lo, hi, gv, gc, gs, -1e9, 1.0, 0.0
            )  # fmt: skip
        cut_j, cut_e = -1, -1
        if cut:
            th_seen, cut_j, cut_e = clamp_to_seen(th, spans[k], lo, hi)
            if cut_j >= 0:
                th, c, s = th_seen, math.cos(th_seen), math.sin(th_seen)
        theta[k, n], cs[0, k, n], cs[1, k, n] = th, c, s
        a0, a1 = rad * c - o0, rad * s - o1
        qd = a0 * d0 + a1 * d1 - o2 * d2
        f = a0 * a0 + a1 * a1 + o2 * o2 - qd * qd
        depth = qd * dz[n]
        if not depth > 1e-6:
            continue
        res = (math.sqrt(max(f, 0.0)) - wire) * focal[n] / depth
        r[k, n] = res
        if not want_system:
            continue
        e0, e1, e2 = a0 - qd * d0, a1 - qd * d1, -o2 - qd * d2
        dist = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        kk = focal[n] / (qd * dz[n])
        inv = 1.0 / max(dist, 1e-12)
        along = (dist - wire) / qd
        g0 = kk * (e0 * inv - along * d0)
        g1 = kk * (e1 * inv - along * d1)
        g2 = kk * (e2 * inv - along * d2)
        P0, P1 = rad * c, rad * s
        w = _irls(res, sigma, loss)
        if not math.isfinite(w):
            continue
        for j in range(6):
            v = (
                (M[j, 0, 0] * P0 + M[j, 0, 1] * P1 + b[j, 0]) * g0
                + (M[j, 1, 0] * P0 + M[j, 1, 1] * P1 + b[j, 1]) * g1
                + (M[j, 2, 0] * P0 + M[j, 2, 1] * P1 + b[j, 2]) * g2
            )
            if cut_j >= 0:  # the cut's end moves along the arc with the pose
                v += dspans[k, j, cut_j, cut_e] * (g1 * P0 - g0 * P1)
            J[j] = v if math.isfinite(v) else 0.0
        for i in range(6):
            wi = w * J[i]
            g[k, i] += wi * res
            for j in range(i, 6):
                A[k, i, j] += wi * J[j]
    if want_system:
        for i in range(6):
            for j in range(i):
                A[k, i, j] = A[k, j, i]


@kernel(parallel=True, fastmath=FAST_MATH)
def edge_system(
    T, T6, steps, origins, dirs, dz, focal, rad, wire, lo, hi, grid, theta_start,
    cs_start, sigma, loss, want_system, spans, dspans,
):  # fmt: skip
    """Residuals r (K, N), nearest angles θ (K, N) and their cos and sin (2, K, N) at poses T
    (K, 4, 4); with ``want_system``, also the normal equations A = Jᵀ W J (K, 6, 6) and
    g = Jᵀ W r (K, 6) of the robust loss (IRLS weights W), J by the poses T6 (K, 6, 4, 4)
    stepped by ``steps``. ``theta_start`` (K, N) with its cos and sin ``cs_start`` (2, K, N)
    seeds the Newton search (an empty array: grid search). Plain arrays and numbers, as
    numba compiles them: :func:`edge_normal_equations` is the typed entry point.

    ``spans`` (K, 2, 2; NaN: none) are the arc's spans the tissue hides (:mod:`tissue_cut`):
    a ray whose nearest arc point is hidden measures to the span's seen end, which moves along
    the arc with the pose by ``dspans`` (K, 6, 2, 2) per parameter."""
    K, N = T.shape[0], origins.shape[0]
    r = np.full((K, N), np.nan)
    theta = np.empty((K, N))
    cs = np.empty((2, K, N))
    A = np.zeros((K, 6, 6))
    g = np.zeros((K, 6))
    seeded = theta_start.shape[0] == K
    cut = spans.shape[0] == K
    gv, gc, gs = angle_grid(lo, hi, grid)
    for k in prange(K):  # poses are independent: the same bits on any number of threads
        edge_pose(
            k, T, T6, steps, origins, dirs, dz, focal, rad, wire, lo, hi, gv, gc, gs,
            theta_start, cs_start, sigma, loss, want_system, seeded, cut, spans, dspans,
            r, theta, cs, A, g,
        )  # fmt: skip
    return r, theta, cs, A, g


_NO_START = np.zeros((0, 0))
_NO_CS = np.zeros((2, 0, 0))
_NO_SPANS = np.zeros((0, 2, 2))
_NO_DSPANS = np.zeros((0, 6, 2, 2))


def edge_normal_equations(
    T: np.ndarray,
    T6: np.ndarray | None,
    steps: np.ndarray,
    rays: EdgeRays,
    model: NeedleModel,
    sigma: float,
    loss: str,
    theta_start: np.ndarray | None = None,
    cs_start: np.ndarray | None = None,
    grid: int = N_THETA_GRID,
):
    """(r, θ, cos and sin of θ, A, g) of :func:`edge_system` at poses T (K, 4, 4); ``T6``
    None: residuals and angles only (A and g zero). ``cs_start``: cos and sin (2, K, N) of
    ``theta_start`` (computed when not given)."""
    if theta_start is not None and cs_start is None:
        cs_start = np.stack([np.cos(theta_start), np.sin(theta_start)])
    K = len(T)
    want = T6 is not None
    spans, dspans = _NO_SPANS, _NO_DSPANS
    if rays.cut is not None:
        if want:
            spans, dspans = rays.cut.spans_and_derivatives(T, T6, steps)
        else:
            spans, dspans = rays.cut.spans(T), np.zeros((K, 6, 2, 2))
        if not np.isfinite(spans).any():
            spans, dspans = _NO_SPANS, _NO_DSPANS
    return edge_system(
        np.ascontiguousarray(T, dtype=float),
        np.ascontiguousarray(T6, dtype=float) if want else np.zeros((K, 6, 4, 4)),
        np.asarray(steps, dtype=float),
        np.ascontiguousarray(rays.origins, dtype=float),
        np.ascontiguousarray(rays.dirs, dtype=float),
        np.ascontiguousarray(rays.dz, dtype=float),
        np.ascontiguousarray(rays.focal, dtype=float),
        float(model.radius),
        float(model.wire_radius),
        float(model.tip_angle),
        float(model.base_angle),
        int(grid),
        _NO_START if theta_start is None else np.ascontiguousarray(theta_start, dtype=float),
        _NO_CS if theta_start is None else np.ascontiguousarray(cs_start, dtype=float),
        float(sigma),
        _LOSS_CODES[loss],
        want,
        spans,
        dspans,
    )
