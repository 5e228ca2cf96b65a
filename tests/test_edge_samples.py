"""Which edge points the fit uses: the subsets, and the outline's two farthest points."""

import numpy as np

from suture_bt.perception.edge_samples import balanced, farthest_pair, subsample


def _all_pairs(pts: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The search over every pair (the reference the hull's shortcut must equal)."""
    p = subsample(pts, 400, rng)
    d = np.sum((p[:, None] - p[None]) ** 2, -1)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return p[i], p[j]


def _half_pixel_clouds(rng: np.random.Generator):
    """Edge-point-like clouds on the half-pixel grid: arcs, scatter, a line, a tiny grid (ties
    of the farthest distance), in shuffled order."""
    for k in range(400):
        n = int(rng.integers(2, 900))
        if k % 4 == 0:
            th = rng.uniform(0.0, 2.2, n)
            p = np.stack([900 + 300 * np.cos(th), 500 + 300 * np.sin(th)], 1)
        elif k % 4 == 1:
            p = rng.uniform(0.0, 60.0, (n, 2))
        elif k % 4 == 2:
            p = np.stack([rng.uniform(0.0, 200.0, n), np.full(n, 7.0)], 1)
        else:
            p = rng.integers(0, 8, (n, 2)).astype(float)
        p = np.unique(np.round(2 * p) / 2, axis=0)
        rng.shuffle(p)
        if len(p) >= 2:
            yield p


def test_farthest_pair_equals_the_all_pairs_search():
    rng = np.random.default_rng(3)
    for pts in _half_pixel_clouds(rng):
        seed = int(rng.integers(1 << 30))
        want = _all_pairs(pts, np.random.default_rng(seed))
        got = farthest_pair(pts, np.random.default_rng(seed))
        np.testing.assert_array_equal(np.stack(got), np.stack(want))


def test_farthest_pair_off_the_half_pixel_grid_searches_every_pair():
    pts = np.random.default_rng(5).uniform(0.0, 100.0, (300, 2))
    np.testing.assert_array_equal(
        np.stack(farthest_pair(pts, np.random.default_rng(0))),
        np.stack(_all_pairs(pts, np.random.default_rng(0))),
    )


def test_balanced_draws_up_to_n_from_each_eye_left_first():
    idx = balanced(50, 8, 10, np.random.default_rng(1))
    assert len(idx) == 18
    assert np.all(idx[:10] < 50) and np.all(idx[10:] >= 50)
    assert np.all(np.diff(idx[:10]) > 0)
