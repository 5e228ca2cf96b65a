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

import functools
import math

import numba
import numpy as np
from numba import prange

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.arc_geometry import _arc_offsets, _ends, _place_offsets
from suture_bt.perception.compiled import kernel
from suture_bt.perception.edge_kernel import angle_grid, edge_pose
from suture_bt.perception.edge_residuals import N_THETA_GRID, EdgeRays
from suture_bt.perception.fit_terms import (
    AWAY_PX_PER_DEG,
    AwayTerm,
    EndPriorTerm,
    _nearer_end_distances,
    away_angle,
)
from suture_bt.perception.needle_projection import _needle_frame_basis, _poses_from_params
from suture_bt.perception.prior_term import PRIOR_PX, HeldPlaceTerm, PriorTerm
from suture_bt.perception.tissue_cut import grid_circle, span_derivatives, spans_of_poses

#: Column blocks of the extra residuals, in the order the terms give them.
_KEYPOINTS, _POINTS, _PLACES, _AWAY = 0, 1, 2, 3


@kernel()
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
            u = r / sigma
            q = 1.0 + u * u  # not u ** 2: see compiled.py
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


@kernel()
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
        elif isinstance(term, AwayTerm):
            # Its rotation's three rows ride in the point rows, its limit in the first's
            # tolerance: the compiled trial's arrays keep their types.
            blocks.append((_AWAY, len(pts), 1))
            pts.extend(term.R)
            tols.extend([term.min_deg, 0.0, 0.0])
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


@kernel()
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
        elif kind == _AWAY:
            R = pts[first : first + 3]
            for k in range(K):
                E[k, col] = AWAY_PX_PER_DEG * max(tols[first] - away_angle(R, T, k), 0.0)
            col += 1
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
    grids = _angle_grid(shape[2], shape[3], N_THETA_GRID) + grid_circle(tissue[6])
    return camera, edge, shape, tissue, terms, grids


@functools.lru_cache(maxsize=8)
def _angle_grid(lo: float, hi: float, grid: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`~.edge_kernel.angle_grid`, made once per needle shape: a parallel kernel's start
    costs about 70 µs, and every LM call of a frame asked for the same grid. The kernels only
    read it (left writeable: a read-only array is another type to numba, compiled anew)."""
    return angle_grid(lo, hi, grid)


#: Trials of at most this many poses run their poses on the calling thread: starting the
#: thread pool's work costs about 10 µs, more than one pose's share of a trial.
SERIAL_MAX_POSES = 1


@kernel()
def lm_trial(x, take_step, A_edge, g_edge, r, E6, extra_w, lam, steps, sigma, loss, stepped,
             theta, cs, fixed):  # fmt: skip
    """One trial: parameters x (K, 6) stepped (``take_step``) by the damped normal equations
    (edge A, g plus the extra terms' from their residuals in r past the edge's and E6), the
    poses T (K, 4, 4) and, when ``stepped``, their copies stepped by ``steps`` (K, 6, 4, 4)
    with the extra terms' residuals there; then the residuals (edge, then extra), nearest arc
    angles seeded by ``theta`` and ``cs`` (empty: grid search) and the edge normal equations
    at T. Returns (x, T, T6, E6, r, θ, cos and sin, A, g); T6 and E6 empty unless stepped.
    Each pose's work is independent of the others' (:func:`_trial_row`), so its poses run
    on numba's threads with the same bits on any number of them."""
    K, N, M = x.shape[0], fixed[1][0].shape[0], fixed[4][10]
    n = steps.shape[0] + 1
    out = (
        np.empty((K, 6)),  # x
        np.empty((K, 4, 4)),  # T
        np.zeros((K, n - 1, 4, 4)),  # T6
        np.empty((K, M)),  # the extra residuals at T
        np.empty((K, n - 1, M)) if stepped else np.zeros((0, n - 1, M)),  # E6
        np.full((K, 2, 2), np.nan),  # the tissue's spans
        np.full((K, 2, 2), -1, np.int64),  # their planes
        np.zeros((K, n - 1, 2, 2)),  # their derivatives
        np.full((K, N), np.nan),  # edge residuals
        np.empty((K, N)),  # nearest arc angles
        np.empty((2, K, N)),  # their cos and sin
        np.zeros((K, 6, 6)),  # A
        np.zeros((K, 6)),  # g
    )
    args = (x, take_step, A_edge, g_edge, r, E6, extra_w, lam, steps, sigma, loss, stepped,
            theta, cs, fixed)  # fmt: skip
    if K <= SERIAL_MAX_POSES:
        _rows_serial(K, args, out)
    else:
        _rows_parallel(K, args, out)
    xn, T, T6, E, E6n, _, _, _, r_edge, th, csn, An, gn = out
    rn = np.empty((K, N + M))
    rn[:, :N] = r_edge
    rn[:, N:] = E
    return xn, T, T6, E6n, rn, th, csn, An, gn


@kernel(parallel=True)
def _rows_parallel(K, args, out):
    """:func:`_trial_row` over the poses on numba's threads. The parallel loop takes arrays
    and numbers only, not tuples of them: the tuples are taken apart here and put together
    again inside it."""
    x, take_step, A_edge, g_edge, r, E6, extra_w, lam, steps, sigma, loss, stepped = args[:12]
    theta, cs, fixed = args[12:]
    camera, edge, shape, tissue, terms, grids = fixed
    fx, fy, cx, cy, Bn, chord, h = camera
    origins, dirs, dz, focal = edge
    rad, wire, lo, hi, grid = shape
    has_cut, P, N, groups, depths, shift, cut_grid = tissue
    blocks, eye_T, eye_k, kps, kp_off, ends, pts, tols, places, arc_ends, n_cols = terms
    gv, gc, gs, cut_gc, cut_gs = grids
    xn, T, T6, E, E6n, spans, planes, dspans, r_edge, th, csn, An, gn = out
    for k in prange(K):  # poses are independent: the same bits on any number of threads
        _trial_row(
            k,
            (x, take_step, A_edge, g_edge, r, E6, extra_w, lam, steps, sigma, loss, stepped,
             theta, cs,
             ((fx, fy, cx, cy, Bn, chord, h), (origins, dirs, dz, focal),
              (rad, wire, lo, hi, grid), (has_cut, P, N, groups, depths, shift, cut_grid),
              (blocks, eye_T, eye_k, kps, kp_off, ends, pts, tols, places, arc_ends, n_cols),
              (gv, gc, gs, cut_gc, cut_gs))),
            (xn, T, T6, E, E6n, spans, planes, dspans, r_edge, th, csn, An, gn),
        )  # fmt: skip


@kernel()
def _rows_serial(K, args, out):
    """:func:`_trial_row` over the poses on the calling thread."""
    for k in range(K):
        _trial_row(k, args, out)


@kernel()
def _trial_row(k, args, out):
    """Pose k of :func:`lm_trial` (its arguments ``args`` and grids; ``out`` its arrays, of
    which this writes row k): the step, the pose and its stepped copies, the extra terms'
    residuals, the tissue's spans with their derivatives, and the edge normal equations."""
    x, take_step, A_edge, g_edge, r, E6, extra_w, lam, steps, sigma, loss, stepped = args[:12]
    theta, cs, fixed = args[12:]
    camera, edge, shape, tissue, terms, grids = fixed
    fx, fy, cx, cy, Bn, chord, h = camera
    origins, dirs, dz, focal = edge
    rad, wire, lo, hi, grid = shape
    has_cut, P, N, groups, depths, shift, cut_grid = tissue
    gv, gc, gs, cut_gc, cut_gs = grids
    xn, T, T6, E, E6n, spans, planes, dspans, r_edge, th, csn, An, gn = out
    M = terms[10]
    n = steps.shape[0] + 1
    if take_step:
        A, g = A_edge[k : k + 1], g_edge[k : k + 1]
        if M:
            n_edge = r.shape[1] - M
            rx = r[k : k + 1, n_edge:]
            A, g = _with_extra_terms(A, g, rx, E6[k : k + 1], extra_w, steps, sigma, loss)
        step = damped_steps(A, g, lam[k : k + 1])
        for i in range(6):
            xn[k, i] = x[k, i] + step[0, i]
    else:
        for i in range(6):
            xn[k, i] = x[k, i]
    flat = np.empty((n, 6))
    for i in range(6):
        flat[0, i] = xn[k, i] + 0.0
        for j in range(1, n):
            flat[j, i] = xn[k, i] + (steps[i] if i == j - 1 else 0.0)
    Pn = _poses_from_params(flat, fx, fy, cx, cy, Bn, chord, h)
    T[k] = Pn[0]
    if stepped:
        T6[k] = Pn[1:]
        if M:
            E_all = _extra_residuals(Pn, terms, rad, lo, hi)
            E[k] = E_all[0]
            E6n[k] = E_all[1:]
    elif M:
        E[k] = _extra_residuals(Pn[:1], terms, rad, lo, hi)[0]
    cut = False
    if has_cut:
        spans_of_poses(k, k + 1, T, P, N, groups, depths, rad, lo, hi, shift, cut_grid, cut_gc,
                       cut_gs, spans, planes)  # fmt: skip
        cut = np.isfinite(spans[k]).any()
        if cut and stepped:
            dT = _pose_differences(T6[k], T[k], steps)
            d = span_derivatives(spans[k : k + 1], planes[k : k + 1], T[k : k + 1], dT, N, rad,
                                 shift)  # fmt: skip
            dspans[k] = d[0]
    seeded = theta.shape[0] == x.shape[0]
    edge_pose(
        k, T, T6, steps, origins, dirs, dz, focal, rad, wire, lo, hi, gv, gc, gs, theta, cs,
        sigma, loss, stepped, seeded, cut, spans, dspans, r_edge, th, csn, An, gn,
    )  # fmt: skip


@kernel()
def _pose_differences(T6, T, steps):
    """The forward differences (1, 6, 4, 4) of one pose T from its stepped copies T6, in
    the arithmetic :meth:`~.tissue_cut.TissueCut.spans_and_derivatives` uses (compiled
    without the edge kernel's licences, which would turn the division into a product)."""
    dT = np.empty((1, T6.shape[0], 4, 4))
    for j in range(T6.shape[0]):
        dT[0, j] = (T6[j] - T) / steps[j]
    return dT
