"""One Levenberg-Marquardt trial of the pose fit as one compiled call.

A trial steps the parameters (damped Gauss-Newton on the edge and extra terms' normal
equations), makes the poses and their finite-difference copies, evaluates the extra terms
(keypoints, priors, held places) and the tissue's cut there, and sums the edge residuals' normal
equations. Each of these was already compiled; called one by one from Python, their calls and
the numpy glue between them cost about 120 µs an iteration, a fifth of a slow frame's time
(development calls of seed 17239218: 21 of 111 ms in the slowest tenth). Here they are one
call, with the same kernels and the same arithmetic in the same order, so a trial gives the
bits the separate calls gave (``tests/test_lm_step.py``).

The extra terms the trial knows are the fit's own (:class:`~.fit_terms.EndPriorTerm`,
:class:`~.prior_term.PriorTerm`, :class:`~.prior_term.HeldPlaceTerm`); a fit with any other
(the experimental free-space term) takes the uncompiled path (:func:`compiled_terms` None).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.arc_geometry import _arc_offsets, _ends, _place_offsets
from suture_bt.perception.edge_kernel import edge_system
from suture_bt.perception.edge_residuals import N_THETA_GRID, EdgeRays
from suture_bt.perception.fit_terms import EndPriorTerm, _nearer_end_distances
from suture_bt.perception.needle_projection import _needle_frame_basis, _poses_from_params
from suture_bt.perception.prior_term import PRIOR_PX, HeldPlaceTerm, PriorTerm
from suture_bt.perception.tissue_cut import hidden_spans, span_derivatives

#: Column blocks of the extra residuals, in the order the terms give them.
_KEYPOINTS, _POINTS, _PLACES = 0, 1, 2


@njit(cache=True)
def _with_extra_terms(A_edge, g_edge, rx, E6, extra_w, steps, sigma, loss_code):
    """The normal equations (K, 6, 6), (K, 6) of the edge residuals plus the extra terms':
    residuals rx (K, M) at the poses, E6 (K, 6, M) at the poses stepped by ``steps``, their
    derivatives by differences, each weighed by ``extra_w`` and the loss's IRLS weight
    (an undefined residual, weight or derivative counts 0). Not the edge kernel's compiled
    weight: that one may fuse multiply-adds, which moves the bits."""
    K, M = rx.shape
    n = steps.shape[0]
    A = A_edge.copy()
    g = g_edge.copy()
    J = np.empty(n)
    for k in range(K):
        for m in range(M):
            r = rx[k, m]
            q = 1.0 + (r / sigma) ** 2
            w = extra_w[m] * (1.0 / q if loss_code == 0 else 1.0 / (q * q))
            if not math.isfinite(w):
                w = 0.0
            if not math.isfinite(r):
                r = 0.0
            for i in range(n):
                d = (E6[k, i, m] - r) / steps[i]
                J[i] = d if math.isfinite(d) else 0.0
            for i in range(n):
                wi = w * J[i]
                g[k, i] += wi * r
                for j in range(n):
                    A[k, i, j] += wi * J[j]
    return A, g


@njit(cache=True)
def damped_steps(A: np.ndarray, g: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt steps -(A + λ (diag A + 1e-9))⁻¹ g per row (K, 6, 6), (K, 6), (K,),
    by Cholesky (A is a Gauss-Newton matrix, so the damped one is positive definite); NaN
    where it is not (the trial then costs inf and the row's damping grows)."""
    K, n = g.shape
    out = np.empty((K, n))
    L = np.empty((n, n))
    y = np.empty(n)
    for k in range(K):
        ok = True
        for i in range(n):
            for j in range(i + 1):
                v = A[k, i, j]
                if i == j:
                    v += lam[k] * (A[k, i, i] + 1e-9)
                for m in range(j):
                    v -= L[i, m] * L[j, m]
                if i == j:
                    if not v > 0.0:
                        ok = False
                        break
                    L[i, i] = np.sqrt(v)
                else:
                    L[i, j] = v / L[j, j]
            if not ok:
                break
        if not ok:
            out[k] = np.nan
            continue
        for i in range(n):  # L y = -g
            v = -g[k, i]
            for m in range(i):
                v -= L[i, m] * y[m]
            y[i] = v / L[i, i]
        for i in range(n - 1, -1, -1):  # Lᵀ x = y
            v = y[i]
            for m in range(i + 1, n):
                v -= L[m, i] * out[k, m]
            out[k, i] = v / L[i, i]
    return out


def start_thread_pool() -> None:
    """Start numba's thread pool if no parallel kernel has yet: the trial calls parallel
    kernels (the edge system, the tissue's spans), and loaded from numba's cache in a fresh
    process before any of them had run it found no pool and crashed (segmentation fault).
    Asking for the pool's size starts it (once; later calls cost a microsecond)."""
    numba.get_num_threads()


def compiled_terms(extras: list, model: NeedleModel):
    """The extra terms as the plain arrays the compiled trial reads, in their column order:
    (blocks (B, 3): kind, first index, count; eye transforms (E, 4, 4), eye intrinsics (E, 4),
    keypoints (·, 2) with each eye's row offsets (E + 1,), the model's ends for the keypoints,
    prior points (·, 3) and tolerances, held places (·, 4: point index, place, its swap's,
    standard deviation), the model's ends for the arc, and the column count); None when a
    term has no compiled form."""
    blocks, eye_T, eye_k, kps, kp_off = [], [], [], [], [0]
    pts, tols, places = [], [], []
    ends = np.zeros((2, 3))
    for term in extras:
        if isinstance(term, EndPriorTerm):
            ends = term.ends
            for cam, T_el, kp in term.eyes:
                blocks.append((_KEYPOINTS, len(eye_T), len(kp)))
                eye_T.append(T_el)
                eye_k.append((cam.fx, cam.fy, cam.cx, cam.cy))
                kps.append(kp)
                kp_off.append(kp_off[-1] + len(kp))
        elif isinstance(term, PriorTerm):  # HeldPlaceTerm too
            first = len(pts)
            pts.extend(term.points)
            tols.extend(term.tolerance)
            if not isinstance(term, HeldPlaceTerm):
                blocks.append((_POINTS, first, len(term.points)))
            start = len(places)
            for i, a, sigma in term.places:
                places.append((first + i, a, model.swapped_angle(a), sigma))
            blocks.append((_PLACES, start, len(term.places)))
        else:
            return None
    n_cols = sum(n * (3 if kind == _POINTS else 1) for kind, _, n in blocks)
    return (
        np.array(blocks, np.int64).reshape(-1, 3),
        np.ascontiguousarray(np.array(eye_T, float).reshape(-1, 4, 4)),
        np.array(eye_k, float).reshape(-1, 4),
        np.ascontiguousarray(np.concatenate(kps) if kps else np.zeros((0, 2))),
        np.array(kp_off, np.int64),
        np.ascontiguousarray(ends, dtype=float),
        np.array(pts, float).reshape(-1, 3),
        np.array(tols, float),
        np.array(places, float).reshape(-1, 4),
        _ends(model),
        n_cols,
    )


@njit(cache=True)
def _extra_residuals(T, terms, radius, tip_angle, base_angle):
    """The extra terms' residuals (K, M) at poses T (K, 4, 4), as each term's own call gives
    them (:meth:`EndPriorTerm.__call__`, :meth:`PriorTerm.__call__`, in the same arithmetic)."""
    blocks, eye_T, eye_k, kps, kp_off, ends, pts, tols, places, arc_ends, n_cols = terms
    K = T.shape[0]
    E = np.empty((K, n_cols))
    col = 0
    for b in range(blocks.shape[0]):
        kind, first, count = blocks[b, 0], blocks[b, 1], blocks[b, 2]
        if kind == _KEYPOINTS:
            e = first
            fx, fy, cx, cy = eye_k[e, 0], eye_k[e, 1], eye_k[e, 2], eye_k[e, 3]
            kp = kps[kp_off[e] : kp_off[e + 1]]
            D = _nearer_end_distances(T, eye_T[e], fx, fy, cx, cy, ends, kp)
            E[:, col : col + count] = D
            col += count
        elif kind == _POINTS:
            off = _arc_offsets(
                T, pts[first : first + count], radius, tip_angle, base_angle, arc_ends
            )
            for k in range(K):
                for q in range(count):
                    for i in range(3):
                        E[k, col + 3 * q + i] = PRIOR_PX * (off[k, q, i] / tols[first + q])
            col += 3 * count
        else:
            for j in range(first, first + count):
                d = _place_offsets(T, pts[int(places[j, 0])], places[j, 1:3])
                for k in range(K):
                    E[k, col] = PRIOR_PX * (d[k] * radius / places[j, 3])
                col += 1
    return E


def trial_arrays(rays: EdgeRays, stereo: StereoCameraModel, model: NeedleModel, terms) -> tuple:
    """What stays fixed over one LM call, as the compiled trial reads it: the camera and
    needle frame, the edge rays, the needle's shape, the tissue's cut and the extra terms."""
    cam = stereo.left
    Bn, chord, h = _needle_frame_basis(model)
    camera = (float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy), Bn, chord, h)
    edge = tuple(np.ascontiguousarray(a, dtype=float) for a in (rays.origins, rays.dirs))
    edge += tuple(np.ascontiguousarray(a, dtype=float) for a in (rays.dz, rays.focal))
    shape = (float(model.radius), float(model.wire_radius), float(model.tip_angle))
    shape += (float(model.base_angle), N_THETA_GRID)
    cut = rays.cut
    if cut is None:
        none = np.zeros((0, 3))
        tissue = (False, none, none, np.zeros(1, np.int64), np.zeros(0), 0.0, np.zeros(0))
    else:
        groups, depths, _, _, _, shift, grid = cut._args
        tissue = (True, cut.points, cut.normals, groups, depths, shift, grid)
    return camera, edge, shape, tissue, terms


@njit(cache=True)
def lm_trial(x, take_step, A_edge, g_edge, r, E6, extra_w, lam, steps, sigma, loss, stepped,
             theta, cs, fixed):  # fmt: skip
    """One trial: parameters x (K, 6) stepped (``take_step``) by the damped normal equations
    (edge A, g plus the extra terms' from their residuals in r past the edge's and E6), the
    poses T (K, 4, 4) and, when ``stepped``, their copies stepped by ``steps`` (K, 6, 4, 4)
    with the extra terms' residuals there; then the residuals (edge, then extra), nearest arc
    angles seeded by ``theta`` and ``cs`` (empty: grid search) and the edge normal equations
    at T. Returns (x, T, T6, E6, r, θ, cos and sin, A, g); T6 and E6 empty unless stepped."""
    camera, edge, shape, tissue, terms = fixed
    fx, fy, cx, cy, Bn, chord, h = camera
    origins, dirs, dz, focal = edge
    rad, wire, lo, hi, grid = shape
    has_cut, P, N, groups, depths, shift, cut_grid = tissue
    n_extra = terms[10]
    K = x.shape[0]
    if take_step:
        A, g = A_edge, g_edge
        if n_extra:
            n_edge = r.shape[1] - n_extra
            A, g = _with_extra_terms(A_edge, g_edge, r[:, n_edge:], E6, extra_w, steps, sigma, loss)
        xn = x + damped_steps(A, g, lam)
    else:
        xn = x.copy()
    n = steps.shape[0] + 1
    flat = np.empty((K * n, 6))
    for k in range(K):
        for i in range(6):
            flat[k * n, i] = xn[k, i] + 0.0
            for j in range(1, n):
                flat[k * n + j, i] = xn[k, i] + (steps[i] if i == j - 1 else 0.0)
    Pn = _poses_from_params(flat, fx, fy, cx, cy, Bn, chord, h)
    T = np.ascontiguousarray(Pn[::n])
    M = terms[10]
    if stepped:
        T6 = np.empty((K, n - 1, 4, 4))
        for k in range(K):
            T6[k] = Pn[k * n + 1 : (k + 1) * n]
        E_all = _extra_residuals(Pn, terms, rad, lo, hi) if M else np.zeros((K * n, 0))
        E = np.ascontiguousarray(E_all[::n])
        E6n = np.empty((K, n - 1, M))
        for k in range(K):
            E6n[k] = E_all[k * n + 1 : (k + 1) * n]
    else:
        T6 = np.zeros((K, n - 1, 4, 4))
        E = _extra_residuals(T, terms, rad, lo, hi) if M else np.zeros((K, 0))
        E6n = np.zeros((0, n - 1, M))
    spans = np.zeros((0, 2, 2))
    dspans = np.zeros((0, n - 1, 2, 2))
    if has_cut:
        s0, planes = hidden_spans(T, P, N, groups, depths, rad, lo, hi, shift, cut_grid)
        if np.isfinite(s0).any():
            spans = s0
            if stepped:
                dT = np.empty((K, n - 1, 4, 4))
                for k in range(K):
                    for j in range(n - 1):
                        dT[k, j] = (T6[k, j] - T[k]) / steps[j]
                dspans = span_derivatives(s0, planes, T, dT, N, rad, shift)
            else:
                dspans = np.zeros((K, n - 1, 2, 2))
    r_edge, th, csn, An, gn = edge_system(
        T, T6, steps, origins, dirs, dz, focal, rad, wire, lo, hi, grid, theta, cs, sigma,
        loss, stepped, spans, dspans,
    )  # fmt: skip
    rn = np.empty((K, r_edge.shape[1] + M))
    rn[:, : r_edge.shape[1]] = r_edge
    rn[:, r_edge.shape[1] :] = E
    return xn, T, T6, E6n, rn, th, csn, An, gn
