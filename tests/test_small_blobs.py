"""without_small_blobs drops blobs under the least area, keeps larger ones and, when asked,
those the array's edge cuts."""

import numpy as np

from suture_bt.perception.small_blobs import without_small_blobs


def _mask() -> np.ndarray:
    m = np.zeros((20, 20), bool)
    m[2:4, 2:4] = True  # 4 px, inside
    m[10:15, 10:15] = True  # 25 px, inside
    m[0:2, 17:19] = True  # 4 px, cut by the top edge
    return m


def test_blobs_under_the_least_area_are_dropped_and_the_rest_kept():
    out = without_small_blobs(_mask(), 5)
    assert out.dtype == bool
    assert not out[2:4, 2:4].any() and not out[0:2, 17:19].any()
    assert out[10:15, 10:15].all()
    assert out.sum() == 25


def test_a_blob_of_exactly_the_least_area_stays():
    assert without_small_blobs(_mask(), 4).sum() == _mask().sum()


def test_edge_cut_blobs_stay_when_asked():
    out = without_small_blobs(_mask(), 5, keep_edge_cut=True)
    assert out[0:2, 17:19].all() and not out[2:4, 2:4].any()
    assert out.sum() == 29


def test_uint8_input_and_an_empty_mask():
    assert without_small_blobs(_mask().astype(np.uint8), 5).sum() == 25
    assert not without_small_blobs(np.zeros((5, 5), np.uint8), 1).any()
