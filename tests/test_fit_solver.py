"""The solver's compiled pieces: the damped Levenberg-Marquardt step and the robust cost."""

import numpy as np
import pytest

from suture_bt.perception.fit_solver import damped_steps, robust_cost


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
