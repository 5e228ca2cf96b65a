"""The compiled LM trial gives the bits of the separate kernels it replaces: the extra terms'
residuals, and whole LM runs with every term the fit uses, with and without the tissue's cut;
a term without a compiled form takes the uncompiled path; a trial's poses, run on numba's
threads, each get the bits a trial of that pose alone gives."""

import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from perception_helpers import MODEL, lm_problem

from suture_bt.perception import fit_solver
from suture_bt.perception.fit_solver import levenberg_marquardt
from suture_bt.perception.lm_step import (
    SERIAL_MAX_POSES,
    _extra_residuals,
    compiled_terms,
    lm_trial,
    trial_arrays,
)
from suture_bt.perception.needle_projection import params_to_pose


def test_the_extra_residuals_are_the_terms_own_bits():
    st, _, x, terms = lm_problem(cut=False)
    steps = np.concatenate([np.zeros((1, 6)), np.diag(fit_solver.FD_STEPS)])
    T = params_to_pose(x[:, None] + steps[None], st.left, MODEL).reshape(-1, 4, 4)
    arrays = compiled_terms(terms, MODEL)
    E = _extra_residuals(T, arrays, MODEL.radius, MODEL.tip_angle, MODEL.base_angle)
    own = np.concatenate([t(T) for t in terms], 1)
    assert E.shape == own.shape == (len(T), 3 + 1 + 2 * 3 + 1)
    assert np.array_equal(E, own)


@pytest.mark.parametrize("cut", [False, True])
@pytest.mark.parametrize("loss", ["cauchy", "geman_mcclure"])
@pytest.mark.parametrize("n_terms", [0, 1, 3])
def test_a_compiled_lm_run_is_the_uncompiled_one_bit_for_bit(cut, loss, n_terms, monkeypatch):
    st, rays, x, terms = lm_problem(cut)
    terms = terms[:n_terms]
    fast = levenberg_marquardt(x, rays, st, MODEL, 6, 1.0, terms, loss)
    monkeypatch.setattr(fit_solver, "compiled_terms", lambda *a: None)
    slow = levenberg_marquardt(x, rays, st, MODEL, 6, 1.0, terms, loss)
    assert np.array_equal(fast[0], slow[0]) and np.array_equal(fast[1], slow[1])
    assert np.isfinite(fast[1]).all()
    if n_terms:  # the terms count: without them the run ends elsewhere
        bare = levenberg_marquardt(x, rays, st, MODEL, 6, 1.0, [], loss)
        assert not np.array_equal(bare[0], fast[0])


class _Flat:
    """A term with no compiled form: a constant residual per pose."""

    def __bool__(self):
        return True

    def __call__(self, T):
        return np.ones((len(T), 1))

    def column_weights(self, n_edge):
        return np.ones(1)


def test_a_term_without_a_compiled_form_takes_the_uncompiled_path():
    st, rays, x, terms = lm_problem(cut=False)
    assert compiled_terms([terms[0], _Flat()], MODEL) is None
    xs, cost = levenberg_marquardt(x, rays, st, MODEL, 3, 1.0, [_Flat()])
    assert xs.shape == x.shape and np.isfinite(cost).all()


_FRESH = """
import sys
sys.path.insert(0, {tests!r})
from perception_helpers import MODEL, lm_problem
from suture_bt.perception.fit_solver import levenberg_marquardt
st, rays, x, terms = lm_problem(True)
print(levenberg_marquardt(x, rays, st, MODEL, 2, 1.0, terms)[1].shape)
"""


def test_a_fresh_process_whose_first_parallel_kernel_is_the_cached_trial_runs_it():
    """The trial's parallel kernels, loaded from numba's cache (the tests above compiled it)
    in a process where no parallel kernel had run yet, crashed until the pool was started."""
    code = _FRESH.format(tests=str(Path(__file__).parent))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "(8,)"


@pytest.mark.parametrize("cut", [False, True])
def test_a_trial_gives_each_pose_the_bits_it_gets_alone_and_on_any_number_of_threads(cut):
    """A trial's poses run on numba's threads (one pose: on the caller's); each pose's
    results are those of a trial of that pose alone (the serial path), whatever the thread
    count, with a step taken and with every term the fit uses."""
    st, rays, x, terms = lm_problem(cut)
    extras = terms
    n_edge = len(rays)
    extra_w = np.ascontiguousarray(np.concatenate([e.column_weights(n_edge) for e in extras]))
    fixed = trial_arrays(rays, st, MODEL, compiled_terms(extras, MODEL))
    lam = np.full(len(x), 1e-2)
    steps = fit_solver.FD_STEPS
    first = lm_trial(x, False, *fit_solver._no_step(len(x)), extra_w, lam, steps, 1.0, 0, True,
                     fit_solver._NO_THETA, fit_solver._NO_CS, fixed)  # fmt: skip
    _, _, _, E6, r, theta, cs, A, g = first
    assert SERIAL_MAX_POSES < len(x)

    def trial(rows):
        return lm_trial(x[rows], True, A[rows], g[rows], r[rows], E6[rows], extra_w, lam[rows],
                        steps, 1.0, 0, True, theta[rows], cs[:, rows], fixed)  # fmt: skip

    together = trial(slice(None))
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        on_one_thread = trial(slice(None))
    finally:
        numba.set_num_threads(threads)
    for k in range(len(x)):
        alone = trial(slice(k, k + 1))
        for i, (a, c) in enumerate(zip(together, alone, strict=True)):
            if i == 6:  # cos and sin hold their rows second
                a, c = a[:, k], c[:, 0]
            else:
                a, c = a[k], c[0]
            assert np.array_equal(a, c, equal_nan=True)
    for a, b in zip(together, on_one_thread, strict=True):
        assert np.array_equal(a, b, equal_nan=True)
    assert np.isfinite(together[4][:, :n_edge]).any()
