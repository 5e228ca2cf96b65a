"""The robust cost's compiled pass gives numpy's bits, on one thread or several; Geman-McClure
caps an outlier's cost where Cauchy keeps growing."""

import os
import subprocess
import sys

import numpy as np
import pytest

from suture_bt.perception import robust_cost as rc
from suture_bt.perception.robust_cost import _numpy_cost, _pairwise_sum, robust_cost

#: Lengths around numpy's pairwise-summation blocks (8, 128 and their halves).
LENGTHS = (1, 7, 8, 9, 15, 16, 127, 128, 129, 255, 256, 257, 401, 1000, 4099)


@pytest.mark.parametrize("n", LENGTHS)
def test_the_pairwise_sum_is_numpys_to_the_bit(n):
    rng = np.random.default_rng(n)
    a = rng.standard_normal(n) * 10.0 ** rng.uniform(-3, 3, n)
    assert _pairwise_sum(a, 0, n) == a.sum()
    assert _pairwise_sum(a, 1, n - 1) == a[1:].sum()  # from an offset


@pytest.mark.parametrize("loss", ["cauchy", "geman_mcclure"])
@pytest.mark.parametrize("rows", [1, 2, 9])
def test_the_compiled_cost_is_numpys_to_the_bit(loss, rows):
    rng = np.random.default_rng(rows)
    for n in LENGTHS:
        r = rng.standard_normal((rows, n)) * rng.uniform(0.1, 6.0)
        w = np.ones(n)
        w[-min(n, 5) :] = 30.0
        sigma = float(rng.uniform(0.3, 3.0))  # some sigma give 0.5 * sigma**2 != 0.5*sigma*sigma
        got = robust_cost(r, sigma, w, loss)
        assert np.array_equal(got, _numpy_cost(r, sigma, w, loss)), n


def test_an_undefined_residual_costs_inf_and_odd_inputs_take_numpy():
    r = np.array([[0.5, np.nan, 1.0], [0.5, 0.2, 1.0], [np.inf, 0.0, 0.0]])
    w = np.array([1.0, 1.0, 30.0])
    got = robust_cost(r, 1.0, w)
    assert got[0] == np.inf and got[2] == np.inf and np.isfinite(got[1])
    assert np.array_equal(
        robust_cost(r[:, ::2], 1.0, w[::2]), _numpy_cost(r[:, ::2], 1.0, w[::2], "cauchy")
    )
    assert robust_cost(r[None], 1.0, w).shape == (1, 3)  # other shapes: numpy
    assert robust_cost(np.zeros((0, 3)), 1.0, w).shape == (0,)


def test_the_same_bits_on_one_thread_and_on_the_pool():
    rng = np.random.default_rng(5)
    r, w = rng.standard_normal((6, 300)), np.ones(300)
    pooled = robust_cost(r, 1.3, w)
    serial = rc._rows_serial(r, 0.5 * 1.3**2, 1.3, w, 0)
    assert np.array_equal(pooled, serial)


_CHILD = """
import os
import subprocess
import sys

import numpy as np
from suture_bt.perception.robust_cost import robust_cost
r = np.random.default_rng(3).standard_normal((4, 1000))
print(robust_cost(r, 1.0, np.ones(1000)).tobytes().hex())
"""


def test_the_kernels_load_from_numbas_disk_cache(tmp_path):
    """Compiled into an empty cache, then loaded from it, in two fresh processes: the same
    bits, and no crash (numba's cache of a recursive function crashes when loaded, so the
    pairwise sum keeps its own stack)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    runs = [
        subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, env=env)
        for _ in range(2)
    ]
    assert [r.returncode for r in runs] == [0, 0], runs[-1].stderr[-500:]
    assert runs[0].stdout == runs[1].stdout and any(tmp_path.rglob("*.nbi"))


def test_geman_mcclure_caps_an_outlier_where_cauchy_keeps_growing():
    r = np.array([[0.0, 0.5, 10.0, 100.0]])
    gm = 2 * robust_cost(r[:, 2:], 1.0, loss="geman_mcclure") / 1.0
    assert 0.98 < gm[0] < 1.0  # both outliers cost almost the cap (σ²/2 each)
    cauchy = robust_cost(r, 1.0)
    assert cauchy[0] > 2 * robust_cost(r, 1.0, loss="geman_mcclure")[0]
    np.testing.assert_allclose(
        robust_cost(r[:, :2], 1.0, loss="geman_mcclure"), robust_cost(r[:, :2], 1.0), rtol=0.15
    )
    with pytest.raises(ValueError, match="unknown loss"):
        robust_cost(r, 1.0, loss="huber")
