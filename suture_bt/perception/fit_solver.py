"""Robust batched Levenberg-Marquardt over the needle parameters, and a fit's predicted spread."""

from __future__ import annotations

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.edge_kernel import _LOSS_CODES, edge_normal_equations
from suture_bt.perception.edge_residuals import EdgeRays, edge_jacobian, residuals
from suture_bt.perception.lm_step import (
    _with_extra_terms,
    compiled_terms,
    damped_steps,
    lm_trial,
    start_thread_pool,
    trial_arrays,
)
from suture_bt.perception.needle_projection import params_to_pose
from suture_bt.perception.prior_term import PriorTerm, prior_information
from suture_bt.perception.robust_cost import robust_cost

#: Finite-difference steps of the six parameters (px, px, px, px, rad, rad) for the pose's
#: derivatives and the extra terms' (the edge residuals' derivatives are analytic).
FD_STEPS = np.array([0.02, 0.02, 0.02, 0.02, 2e-5, 2e-4])
#: No step, then FD_STEPS in each parameter in turn (rows of a pose and its stepped poses).
_STEPS = np.concatenate([np.zeros((1, 6)), np.diag(FD_STEPS)])


def _irls_weights(r: np.ndarray, sigma: float, loss: str) -> np.ndarray:
    """IRLS weights ψ(r)/r of the loss."""
    q = 1.0 + (r / sigma) ** 2
    return 1.0 / q if loss == "cauchy" else 1.0 / q**2


def _pose_derivatives(x: np.ndarray, T: np.ndarray, cam, model: NeedleModel):
    """Poses stepped by FD_STEPS in each of the six parameters (K, 6, 4, 4) and the forward
    differences dT/dx (K, 6, 4, 4) at the poses T (K, 4, 4) of parameters x (K, 6)."""
    T6 = params_to_pose(x[:, None, :] + np.diag(FD_STEPS)[None], cam, model)
    return T6, (T6 - T[:, None]) / FD_STEPS[None, :, None, None]


def levenberg_marquardt(
    x: np.ndarray,
    rays: EdgeRays,
    stereo: StereoCameraModel,
    model: NeedleModel,
    iters: int,
    sigma: float,
    extra=None,
    loss: str = "cauchy",
) -> tuple[np.ndarray, np.ndarray]:
    """Batched robust LM over starts x (K, 6); returns (x, cost).

    ``extra`` (a term or a list of terms: ``term(T) -> (K, M)`` residuals in px, and
    ``term.column_weights(n_edge)``) adds residuals (free space, keypoint prior) to the edge
    residuals. The edge residuals and their normal equations come from the compiled loop
    (:mod:`edge_kernel`); the extra terms' derivatives are finite differences. When every
    extra term has a compiled form, each trial is one compiled call (:mod:`lm_step`), with
    the same bits.
    """
    x = np.array(x, dtype=float)
    cam = stereo.left
    extras = [e for e in (extra if isinstance(extra, list | tuple) else [extra]) if e]
    K, n_edge = len(x), len(rays)
    extra_w = np.concatenate([e.column_weights(n_edge) for e in extras]) if extras else None
    colw = np.concatenate([np.ones(n_edge)] + ([extra_w] if extras else []))

    def extra_residuals(T):
        return np.concatenate([e(T) for e in extras], 1)

    def with_steps(x, stepped: bool = True):
        """Poses of x and of x stepped by FD_STEPS in each parameter, in one batch (each
        pose's bits do not depend on its batch): (K, 4, 4), (K, 6, 4, 4), and the extra
        terms' residuals at the poses (K, M) and at the stepped poses (K, 6, M), also in one
        batch (None without extra terms; the stepped ones also without ``stepped``: the last
        trial's derivatives are never used)."""
        P = params_to_pose(x[:, None, :] + _STEPS[None], cam, model)
        T = np.ascontiguousarray(P[:, 0])
        if not stepped:
            return T, None, (extra_residuals(T) if extras else None), None
        if not extras:
            return T, P[:, 1:], None, None
        E = extra_residuals(P.reshape(-1, 4, 4)).reshape(K, 7, -1)
        return T, P[:, 1:], E[:, 0], E[:, 1:]

    def evaluate(T, T6, E, theta=None, cs=None):
        """Residuals (edge, then the extra ones E), nearest angles with their cos and sin,
        and the edge normal equations."""
        r, th, cs, A, g = edge_normal_equations(
            T, T6, FD_STEPS, rays, model, sigma, loss, theta, cs
        )
        return (np.concatenate([r, E], 1) if extras else r), th, cs, A, g

    code = _LOSS_CODES[loss]
    compiled = compiled_terms(extras, model)
    if compiled is not None:
        start_thread_pool()
        fixed = trial_arrays(rays, stereo, model, compiled)
        w = np.ascontiguousarray(colw[n_edge:])

        def trial(x, state, lam, stepped, theta=_NO_THETA, cs=_NO_CS):
            """One compiled trial (:func:`~.lm_step.lm_trial`); ``state`` None: no step."""
            step = state is not None
            A, g, r, E6 = state if step else _no_step(len(x))
            return lm_trial(
                x, step, A, g, r, E6, w, lam, FD_STEPS, sigma, code, stepped, theta, cs, fixed
            )

    else:

        def trial(x, state, lam, stepped, theta=None, cs=None):
            """The same trial from the separate kernels (a term without a compiled form)."""
            if state is not None:
                A, g, r, E6 = state
                if extras:
                    # The extra terms' part: derivatives by differences (the stepped poses'
                    # residuals were made with the trial poses of the previous iteration).
                    rx = np.ascontiguousarray(r[:, n_edge:])
                    A, g = _with_extra_terms(A, g, rx, E6, extra_w, FD_STEPS, sigma, code)
                x = x + damped_steps(A, g, lam)
            T, T6, E, E6 = with_steps(x, stepped)
            return (x, T, T6, E6, *evaluate(T, T6, E, theta, cs))

    return _lm_loop(x, trial, iters, sigma, colw, loss)


_NO_THETA = np.zeros((0, 0))
_NO_CS = np.zeros((2, 0, 0))


def _no_step(K: int) -> tuple:
    """Normal equations, residuals and stepped extra residuals of no step (typed for numba)."""
    return np.zeros((K, 6, 6)), np.zeros((K, 6)), np.zeros((K, 0)), np.zeros((K, 6, 0))


def _lm_loop(x: np.ndarray, trial, iters: int, sigma: float, colw, loss: str):
    """Levenberg-Marquardt over the rows of x: each iteration's ``trial`` (x, (A, g, r, E6) of
    the current poses or None for no step, damping, whether the stepped poses are wanted,
    nearest arc angles with their cos and sin) → (x, T, T6, E6, r, θ, cos and sin, A, g) is
    taken where it lowers a row's robust cost; (x, cost)."""
    lam = np.full(len(x), 1e-2)
    x, T, T6, E6, r, theta, cs, A_edge, g_edge = trial(x, None, lam, True)
    cost = robust_cost(r, sigma, colw, loss)
    for it in range(iters):
        if not np.isfinite(cost).any():
            break
        last = it == iters - 1  # its trial's residuals decide; its derivatives are unused
        xn, Tn, T6n, E6n, rn, thn, csn, An, gn = trial(
            x, (A_edge, g_edge, r, E6), lam, not last, theta, cs
        )
        cn = robust_cost(rn, sigma, colw, loss)
        better = cn < cost
        if last:
            x[better], cost[better] = xn[better], cn[better]
            break
        x, T, T6, E6, r, theta, cs, A_edge, g_edge, cost = _take_better(
            better,
            (x, T, T6, E6, r, theta, cs, A_edge, g_edge, cost),
            (xn, Tn, T6n, E6n, rn, thn, csn, An, gn, cn),
        )
        lam = np.where(better, lam / 3.0, lam * 4.0)
        lam = np.clip(lam, 1e-7, 1e7)
    return x, cost


def _take_better(better: np.ndarray, state: tuple, trial: tuple) -> tuple:
    """The LM state (x, T, T6, E6, r, θ, cos and sin, A, g, cost) with the rows whose trial was
    cheaper (``better``) taken from ``trial`` (the same fields; cos and sin hold their rows
    second; E6 None: no extra terms). Every trial taken (common early on): the trial itself,
    without row-wise copies."""
    if better.all():
        return trial
    if better.any():
        for i, (old, new) in enumerate(zip(state, trial, strict=True)):
            if old is None:
                continue
            # In place under a mask: no gathered copies (a third of the time indexing took).
            rows = (
                better[None, :, None] if i == 6 else better.reshape((-1,) + (1,) * (old.ndim - 1))
            )
            np.copyto(old, new, where=rows)
    return state


def pose_uncertainty(
    x: np.ndarray,
    rays: EdgeRays,
    stereo: StereoCameraModel,
    model: NeedleModel,
    sigma: float = 1.0,
    loss: str = "geman_mcclure",
    prior: PriorTerm | None = None,
) -> tuple[float, float]:
    """Predicted spread of a fitted pose: (angle std in degrees, arc-centre std in mm).

    The Gauss-Newton covariance (Jᵀ W J / s² + I_prior)⁻¹ of the robust edge fit at
    parameters ``x`` (W the loss's IRLS weights, s² their weighted residual variance; I_prior
    the task priors' information, :func:`~suture_bt.perception.prior_term.prior_information`,
    when ``prior`` is given), carried to the needle frame's rotation and origin. It is large
    where the seen outline (and the priors) leave the pose free: a short, nearly straight
    visible piece fixes neither the arc's plane nor how it goes on behind an occluder.
    Neighbouring edge residuals are treated as independent (they are not), so it ranks views
    by how firmly they pin the pose; it is not a calibrated standard deviation.
    """
    cam = stereo.left
    x = np.asarray(x, dtype=float)[None]
    T = params_to_pose(x, cam, model)
    r, theta = residuals(T, rays, model)
    T6, dT = _pose_derivatives(x, T, cam, model)
    J = edge_jacobian(T, dT, rays, model, theta)[0]
    r = r[0]
    ok = np.isfinite(r) & np.isfinite(J).all(0)
    if ok.sum() <= len(FD_STEPS):
        return float("inf"), float("inf")
    J, r = J[:, ok], r[ok]
    w = _irls_weights(r, sigma, loss)
    s2 = float((w * r * r).sum() / max(w.sum() - len(FD_STEPS), 1.0))
    info = (J * w) @ J.T / s2 + prior_information(prior, T[0], T6[0], FD_STEPS)
    cov = np.linalg.pinv(info)
    # Per parameter: the small rotation R0ᵀ dR (the axial vector of its skew part) and the
    # origin's shift.
    S = np.einsum("ji,kjl->kil", T[0, :3, :3], dT[0, :, :3, :3])
    J_rot = 0.5 * np.stack(
        [S[:, 2, 1] - S[:, 1, 2], S[:, 0, 2] - S[:, 2, 0], S[:, 1, 0] - S[:, 0, 1]]
    )
    J_pos = dT[0, :, :3, 3].T
    var_rot = max(float(np.trace(J_rot @ cov @ J_rot.T)), 0.0)
    var_pos = max(float(np.trace(J_pos @ cov @ J_pos.T)), 0.0)
    return float(np.degrees(np.sqrt(var_rot))), float(1e3 * np.sqrt(var_pos))
