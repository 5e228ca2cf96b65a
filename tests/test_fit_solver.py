"""The solver's compiled pieces: the damped Levenberg-Marquardt step, the extra terms' normal
equations and the robust cost."""

import numpy as np
import pytest

from suture_bt.perception.fit_solver import (
    FD_STEPS,
    _irls_weights,
    _take_better,
    _with_extra_terms,
    damped_steps,
    robust_cost,
)


def _gauss_newton(seed: int, k: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(k, 6, 40)) * np.array([1.0, 1.0, 1.0, 1.0, 1e3, 1e2])[None, :, None]
    return J @ J.transpose(0, 2, 1), rng.normal(size=(k, 6)), 10.0 ** rng.uniform(-7, 3, k)


def test_the_damped_step_solves_the_damped_normal_equations():
    A, g, lam = _gauss_newton(3)
    step = damped_steps(A, g, lam)
    damped = A + lam[:, None, None] * (np.eye(6) * (np.einsum("kii->ki", A) + 1e-9)[:, None, :])
    np.testing.assert_allclose(np.einsum("kij,kj->ki", damped, step), -g, atol=1e-9)


def test_a_row_that_is_not_positive_definite_gets_no_step_and_the_others_theirs():
    A, g, lam = _gauss_newton(4, k=3)
    A[1] = -np.eye(6)  # not a Gauss-Newton matrix: no Cholesky factor
    step = damped_steps(A, g, lam)
    assert np.isnan(step[1]).all()
    assert np.isfinite(step[[0, 2]]).all()


def test_the_robust_cost_is_the_weighted_mean_loss_and_inf_where_undefined():
    r = np.array([[0.0, 1.0, 2.0], [1.0, np.nan, 0.0]])
    w = np.array([1.0, 2.0, 1.0])
    cauchy = 0.5 * np.log1p(np.array([0.0, 1.0, 4.0]))
    assert robust_cost(r, 1.0)[0] == pytest.approx(cauchy.mean())
    assert robust_cost(r, 1.0, w)[0] == pytest.approx((cauchy * w).sum() / w.sum())
    gm = 0.5 * 4.0 * np.array([0.0, 0.25, 1.0]) / np.array([1.0, 1.25, 2.0])
    assert robust_cost(r, 2.0, None, "geman_mcclure")[0] == pytest.approx(gm.mean())
    assert robust_cost(r, 1.0)[1] == np.inf
    assert robust_cost(r[None], 1.0).shape == (1, 2)  # any leading shape


@pytest.mark.parametrize("code, loss", [(0, "cauchy"), (1, "geman_mcclure")])
def test_the_extra_terms_add_their_weighted_difference_jacobian_to_the_normal_equations(code, loss):
    A, g, _ = _gauss_newton(5, k=4)
    rng = np.random.default_rng(6)
    rx = rng.normal(size=(4, 9)) * 3.0
    E6 = rx[:, None, :] + rng.normal(size=(4, 6, 9)) * FD_STEPS[None, :, None]
    rx[1, 2] = np.nan  # an undefined residual counts 0 (its weight and derivatives too)
    E6[2, 3, 4] = np.inf  # an undefined stepped residual: that derivative counts 0
    w_col = rng.uniform(0.5, 2.0, 9)
    A2, g2 = _with_extra_terms(A, g, rx, E6, w_col, FD_STEPS, 1.5, code)
    # The same sums in numpy (the solver's formula before it was compiled).
    w = w_col * _irls_weights(rx, 1.5, loss)
    w = np.where(np.isfinite(w), w, 0.0)
    r = np.where(np.isfinite(rx), rx, 0.0)
    J = (E6 - r[:, None]) / FD_STEPS[None, :, None]
    J = np.where(np.isfinite(J), J, 0.0)
    Jw = J * w[:, None, :]
    np.testing.assert_allclose(A2, A + Jw @ J.transpose(0, 2, 1), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(g2, g + (Jw @ r[..., None])[..., 0], rtol=1e-12, atol=1e-9)
    assert np.isfinite(A2).all() and np.isfinite(g2).all()
    assert not np.shares_memory(A2, A)  # the edge part is left as it was


def test_take_better_takes_exactly_the_cheaper_rows_of_every_field():
    """The LM state's rows whose trial was cheaper come from the trial, in every field (cos
    and sin hold their rows second; E6 may be absent); all or none taken: one or the other."""
    rng = np.random.default_rng(0)
    K = 5
    shapes = [(K, 6), (K, 4, 4), (K, 6, 4, 4), (K, 6, 3), (K, 9), (K, 7), (2, K, 7), (K, 6, 6)]
    shapes += [(K, 6), (K,)]

    def fields():
        out = [rng.random(s) for s in shapes]
        out[3] = None  # no extra terms
        return tuple(out)

    state, trial = fields(), fields()
    before = tuple(None if a is None else a.copy() for a in state)
    better = np.array([True, False, True, False, False])
    got = _take_better(better, state, trial)
    assert got is state
    for i, (g, b, t) in enumerate(zip(got, before, trial, strict=True)):
        if g is None:
            continue
        rows = (slice(None), better) if i == 6 else (better,)
        keep = (slice(None), ~better) if i == 6 else (~better,)
        assert np.array_equal(g[rows], t[rows]) and np.array_equal(g[keep], b[keep]), i
    assert _take_better(np.ones(K, bool), state, trial) is trial
    same = tuple(None if a is None else a.copy() for a in state)
    assert _take_better(np.zeros(K, bool), state, trial) is state
    assert all(a is None or np.array_equal(a, c) for a, c in zip(state, same, strict=True))
