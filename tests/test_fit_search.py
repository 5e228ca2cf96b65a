"""The fit's start search: too few edge points is NeedleNotFound, each end hypothesis is
recorded and its cheapest starts come first, the second search starts from the best pose's own
ends (and a close rival's), and how far the best pose's ends lie from the first hypothesis."""

import numpy as np
import pytest
from perception_helpers import MODEL, _scene_1080p, pose_errors, recorded_fit

from suture_bt.perception.fit_search import StartSearch
from suture_bt.perception.fit_starts import ends_moved
from suture_bt.perception.mask_view import MaskView
from suture_bt.perception.needle_projection import end_pixels, pose_to_params
from suture_bt.perception.pose_fit import NeedleNotFound, PoseFitter
from suture_bt.transforms import make_transform


def _search(seed: int = 3):
    st, T, left, right, ends = _scene_1080p(seed, 0.0)
    fitter = PoseFitter(st, MODEL)
    return fitter, StartSearch.begin(fitter, left, right, None, ()), T, ends


def test_too_few_edge_points_is_needle_not_found():
    st, _, left, _, _ = _scene_1080p(3, 0.0)
    speck = np.zeros((4, 4), bool)
    speck[1, 1] = True  # 4 edge points, under min_edge_points
    with pytest.raises(NeedleNotFound, match="too few needle edge points"):
        StartSearch.begin(PoseFitter(st, MODEL), left, MaskView(speck, (0, 0)), None, ())


def test_the_true_pose_is_the_cheapest_start_and_infeasible_ones_are_dropped():
    fitter, search, T, _ = _search()
    cam = fitter.stereo.left
    x_true = pose_to_params(T[None], cam, MODEL)
    turned = [T @ make_transform(np.eye(3), (0.0, 0.0, dz)) for dz in (0.004, -0.006, 0.01)]
    x_off = pose_to_params(np.stack(turned), cam, MODEL)
    nan_row = np.full((1, 6), np.nan)  # no pose: infinite cost, never kept
    rows = np.concatenate([x_off, nan_row, x_true])
    kept = search.lowest(rows, 3)
    assert len(kept) == 3
    np.testing.assert_array_equal(kept[0], x_true[0])
    assert not np.isnan(kept).any()
    assert len(search.lowest(rows, 10)) == 4


def test_each_end_hypothesis_is_recorded_and_its_starts_keep_its_end_pixels():
    fitter, search, T, ends = _search()
    starts = search.best_starts(tuple(ends), float(T[2, 3]), 5)
    assert len(starts) == 5
    np.testing.assert_allclose(starts[:, :4], np.broadcast_to(ends.ravel(), (5, 4)))
    # None: the left outline's farthest pair, within a few px (the wire's half-width and
    # its caps) of the true end pixels.
    search.best_starts(None, None, 5)
    assert len(search.tried) == 2
    np.testing.assert_array_equal(search.tried[0], ends)
    assert ends_moved(ends, search.tried[1:]) < 6.0


@pytest.mark.parametrize("ratio, n_hypotheses", [(0.0, 1), (1e6, 2)])
def test_the_second_search_starts_from_the_best_pose_and_a_close_rival(ratio, n_hypotheses):
    fitter, search, T, ends = _search()
    cam = fitter.stereo.left
    other = T.copy()
    other[:3, :3] = T[:3, :3] @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    x = pose_to_params(np.stack([other, T]), cam, MODEL)
    cost = np.array([2.0, 1.0])  # T is the best, ``other`` (90 deg away) costs twice as much
    starts = search.reseed_starts(x, cost, ratio)
    assert len(search.tried) == n_hypotheses
    # The best pose's own end pixels come first, its depth the hint.
    np.testing.assert_allclose(search.tried[0], end_pixels(cam, T, MODEL), atol=1e-9)
    assert 0 < len(starts) <= n_hypotheses * fitter.n_reseed
    np.testing.assert_allclose(starts[0, :4], end_pixels(cam, T, MODEL).ravel(), atol=1e-9)


def test_best_ends_moved_measures_the_cheapest_row_from_the_first_hypothesis():
    fitter, search, T, ends = _search()
    cam = fitter.stereo.left
    search.best_starts(tuple(ends), None, 1)
    search.best_starts(tuple(ends + 40.0), None, 1)  # later hypotheses do not count
    shifted = T.copy()
    shifted[0, 3] += 0.002
    x = pose_to_params(np.stack([shifted, T]), cam, MODEL)
    assert search.best_ends_moved(x, np.array([2.0, 1.0])) < 1e-6
    moved = np.linalg.norm(end_pixels(cam, shifted, MODEL) - ends, axis=1).max()
    assert search.best_ends_moved(x, np.array([1.0, 2.0])) == pytest.approx(moved)
    assert search.best_ends_moved(x, np.array([np.inf, np.inf])) == 0.0


def test_a_needle_seen_only_outside_its_entry_port_is_found_from_the_entry_starts():
    """Held-out report 78041143 `in_port` #29 without priors (session 41): only the wire
    outside the entry port is seen (the tip's piece out of the exit is not in the mask), about
    27° of arc, nearly straight. Kept by coarse cost, 6 entry starts missed the true turn
    about the chord and the fit settled on an arc curling back into the tissue, 19 mm off;
    the default keeps enough to find the true pose, which also costs less."""
    fitter, args, kwargs, T = recorded_fit("seen_outside_the_entry")
    found = fitter.fit(*args, **kwargs)
    mm, deg = min(pose_errors(found.T_cam_needle, t) for t in (T, MODEL.swapped(T)))
    assert mm < 0.5 and deg < 2.0, (mm, deg)
    fitter.n_keep_entry = 6
    missed = fitter.fit(*args, **kwargs)
    mm6, deg6 = min(pose_errors(missed.T_cam_needle, t) for t in (T, MODEL.swapped(T)))
    assert mm6 > 10.0 and deg6 > 45.0, (mm6, deg6)
    assert found.cost < 0.9 * missed.cost
