"""The fit's starts and its pick of poses to carry on: the start grid keeps the end pixels
and spans depths × turns, and distinct basins go before copies of the best."""

import numpy as np
import pytest
from perception_helpers import MODEL, random_needle_pose, stereo
from scipy.spatial.transform import Rotation

from suture_bt.perception.fit_starts import (
    DISTINCT,
    diverse,
    ends_moved,
    rot_angle,
    start_params,
)
from suture_bt.perception.needle_projection import params_to_pose, pose_to_params


def test_start_grid_keeps_the_end_pixels_and_spans_the_turns_and_depths():
    st = stereo(1920, 1080)
    T = random_needle_pose(np.random.default_rng(5), 0.08, 0.12)
    x = pose_to_params(T[None], st.left, MODEL)[0]
    ub, ut = x[:2], x[2:4]
    grid = start_params(ub, ut, float(T[2, 3]), st.left, MODEL, n_psi=12)
    assert grid.shape[1] == 6 and len(grid) % 12 == 0
    assert np.allclose(grid[:, :2], ub) and np.allclose(grid[:, 2:4], ut)
    assert len(np.unique(np.round(grid[:, 5], 9))) == 12
    depths = params_to_pose(grid, st.left, MODEL)[:, 2, 3]
    finite = depths[np.isfinite(depths)]
    # With a depth hint the starts lie about it (0.8-1.25 of it), not over the whole range.
    assert finite.min() > 0.5 * T[2, 3] and finite.max() < 2.0 * T[2, 3]
    blind = start_params(ub, ut, None, st.left, MODEL, n_psi=12)
    assert len(blind) > len(grid)


def test_second_stage_starts_are_distinct_basins_before_copies():
    """Copies of the best basin do not crowd out a clearly different, slightly worse one."""
    st = stereo(1920, 1080)
    rng = np.random.default_rng(3)
    T = random_needle_pose(rng, 0.08, 0.12)
    other = T.copy()
    other[:3, :3] = T[:3, :3] @ Rotation.from_euler("x", 40, degrees=True).as_matrix()
    x = pose_to_params(np.stack([T, T, T, other]), st.left, MODEL)
    x[1:3, :2] += 0.3  # near-copies of the best, a fraction of a pixel apart
    cost = np.array([1.0, 1.01, 1.02, 1.5])
    assert list(diverse(x, cost, 2, st.left, MODEL)) == [0, 3]
    assert list(diverse(x, cost, 3, st.left, MODEL)) == [0, 3, 1]
    assert list(diverse(x, np.full(4, np.inf), 2, st.left, MODEL)) == [0, 1]
    assert np.isclose(rot_angle(T[:3, :3], other[:3, :3]), np.deg2rad(40.0)) and DISTINCT < 0.7


def test_ends_moved_is_the_farther_end_from_the_nearest_hypothesis_either_way_round():
    ends = np.array([[100.0, 100.0], [130.0, 100.0]])
    tried = [
        (np.array([100.0, 103.0]), np.array([130.0, 104.0])),  # 4 px (its farther end)
        (np.array([131.0, 100.0]), np.array([100.0, 102.0])),  # swapped: 2 px
    ]
    assert ends_moved(ends, tried) == pytest.approx(2.0)
    assert ends_moved(ends, tried[:1]) == pytest.approx(4.0)
    assert ends_moved(ends, []) == float("inf")
