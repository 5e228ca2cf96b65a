"""The fit's robust cost per start: the (weighted) mean robust loss of its residuals.

The solver weighs every trial of every start by it (:func:`~.fit_solver.levenberg_marquardt`),
about a hundred times a frame. In numpy that is eight passes over a (starts × residuals) array
and 9 ms of a development frame's 134 (cached calls of seed 17239218, session 50). The
weighted cost is also one compiled pass here, its rows on numba's threads, with the bits numpy
gives: the same products in the same order, and numpy's own pairwise summation
(:func:`_pairwise_sum`, numpy's ``pairwise_sum``: eight running sums in blocks of at most 128,
halves above that). ``tests/test_robust_cost.py`` holds the two to the same bits.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from suture_bt.perception.compiled import kernel

#: Robust losses of the fit: Cauchy (outliers grow logarithmically; a wide basin for the
#: search) and Geman-McClure (outliers cost a constant; the pose that explains the most edge
#: points tightly wins, however a few stray mask pixels lie).
LOSSES = ("cauchy", "geman_mcclure")
#: numpy's pairwise summation: fewer values than this are summed one by one...
_UNROLL = 8
#: ...at most this many in eight running sums, more split in halves (numpy's PW_BLOCKSIZE).
_BLOCK = 128
#: Costs of at most this many starts are summed on the calling thread: starting the thread
#: pool's work costs more than one row's share.
SERIAL_MAX_ROWS = 1


def robust_cost(
    r: np.ndarray, sigma: float, weights: np.ndarray | None = None, loss: str = "cauchy"
) -> np.ndarray:
    """(Weighted) mean robust loss per start (inf where any residual is undefined); rows of
    residuals (K, L) with weights (L,) take the compiled pass, with the same bits."""
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}; expected one of {LOSSES}")
    if weights is not None and r.ndim == 2 and r.dtype == np.float64 and len(r):
        w = np.ascontiguousarray(weights, dtype=np.float64)
        if w.shape == (r.shape[1],):
            # numpy's 0.5 * sigma**2 (Python's power), not the kernel's product: they differ
            # in the last bit for some sigma.
            half = 0.5 * sigma**2
            rows = _rows_serial if len(r) <= SERIAL_MAX_ROWS else _rows_parallel
            return rows(np.ascontiguousarray(r), half, float(sigma), w, LOSSES.index(loss))
    return _numpy_cost(r, sigma, weights, loss)


def _numpy_cost(r, sigma, weights, loss) -> np.ndarray:
    """The cost in numpy (any leading shape, weighted or not)."""
    x2 = (r / sigma) ** 2
    c = 0.5 * sigma**2 * (np.log1p(x2) if loss == "cauchy" else x2 / (1.0 + x2))
    out = c.mean(-1) if weights is None else (c * weights).sum(-1) / weights.sum()
    return np.where(np.isfinite(out), out, np.inf)


@kernel()
def _pairwise_sum(a, lo, n):
    """Sum of a[lo : lo + n] as numpy's ``pairwise_sum`` adds it (its bits): blocks of at
    most _BLOCK summed by :func:`_block_sum`, longer runs split in halves (rounded down to a
    multiple of _UNROLL) and their sums added. The halving runs on an explicit stack: numba's
    on-disk cache of a recursive function crashes when it is loaded."""
    if n <= _BLOCK:
        return _block_sum(a, lo, n)
    starts = np.empty(64, np.int64)  # the stack: 2**64 values would be needed to overflow it
    sizes = np.empty(64, np.int64)
    stages = np.zeros(64, np.int64)  # 0: sum the first half next, 1: the second, 2: add them
    firsts = np.empty(64)
    starts[0], sizes[0] = lo, n
    top, last = 0, 0.0
    while top >= 0:
        start, size = starts[top], sizes[top]
        if size <= _BLOCK:
            last = _block_sum(a, start, size)
            top -= 1
            continue
        half = size // 2
        half -= half % _UNROLL
        if stages[top] == 0:
            stages[top] = 1
            top += 1
            starts[top], sizes[top], stages[top] = start, half, 0
        elif stages[top] == 1:
            firsts[top], stages[top] = last, 2
            top += 1
            starts[top], sizes[top], stages[top] = start + half, size - half, 0
        else:
            last = firsts[top] + last
            top -= 1
    return last


@kernel()
def _block_sum(a, lo, n):
    """numpy's sum of at most _BLOCK values a[lo : lo + n]: one by one below _UNROLL, else
    in eight running sums added as a tree, then the rest one by one."""
    if n < _UNROLL:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = _UNROLL
    while i < n - n % _UNROLL:
        j = lo + i
        r0, r1, r2, r3 = r0 + a[j], r1 + a[j + 1], r2 + a[j + 2], r3 + a[j + 3]
        r4, r5, r6, r7 = r4 + a[j + 4], r5 + a[j + 5], r6 + a[j + 6], r7 + a[j + 7]
        i += _UNROLL
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@kernel()
def _row_cost(r, k, half, sigma, w, w_sum, loss, out):
    """Row k's weighted mean loss into out[k] (inf where undefined), in numpy's order:
    ((0.5 σ²) · ρ(x²)) · w, summed pairwise, over the weights' sum."""
    L = r.shape[1]
    c = np.empty(L)
    for j in range(L):
        u = r[k, j] / sigma
        x2 = u * u
        rho = math.log1p(x2) if loss == 0 else x2 / (1.0 + x2)
        c[j] = half * rho * w[j]
    s = _pairwise_sum(c, 0, L) / w_sum
    out[k] = s if math.isfinite(s) else np.inf


@kernel()
def _rows_serial(r, half, sigma, w, loss):
    """:func:`_row_cost` of every row on the calling thread."""
    out = np.empty(r.shape[0])
    w_sum = _pairwise_sum(w, 0, w.shape[0])
    for k in range(r.shape[0]):
        _row_cost(r, k, half, sigma, w, w_sum, loss, out)
    return out


@kernel(parallel=True)
def _rows_parallel(r, half, sigma, w, loss):
    """:func:`_row_cost` of every row on numba's threads (rows are independent: the same
    bits on any number of threads)."""
    out = np.empty(r.shape[0])
    w_sum = _pairwise_sum(w, 0, w.shape[0])
    for k in prange(r.shape[0]):
        _row_cost(r, k, half, sigma, w, w_sum, loss, out)
    return out
