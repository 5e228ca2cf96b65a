"""The visible needle's ends by distance along its mask."""

import cv2
import numpy as np

from suture_bt.perception.geodesic_ends import geodesic_ends
from suture_bt.perception.pose_fit import MaskView, mask_ends


def _polyline_mask(points, shape=(80, 120), thickness=3) -> np.ndarray:
    img = np.zeros(shape, np.uint8)
    cv2.polylines(img, [np.array(points, np.int32)], False, 1, thickness)
    return img.astype(bool)


def _near(p, q, tol=3.0) -> bool:
    return float(np.linalg.norm(np.asarray(p) - np.asarray(q))) <= tol


def test_a_folded_arc_gives_its_two_ends_not_its_bend():
    """A V whose ends are 60 px apart and whose bend sticks out 95 px from each: the
    straight-line farthest pair takes the bend, the distance along the mask does not."""
    a, bend, c = (10, 10), (100, 40), (10, 70)
    view = MaskView(_polyline_mask([a, bend, c]), (100, 200))
    ends = geodesic_ends(view)
    shifted = [np.add(p, (100, 200)) for p in (a, c)]
    assert (_near(ends[0], shifted[0]) and _near(ends[1], shifted[1])) or (
        _near(ends[0], shifted[1]) and _near(ends[1], shifted[0])
    )
    assert any(_near(p, np.add(bend, (100, 200)), 4.0) for p in mask_ends(view))


def test_the_largest_piece_is_used_and_an_empty_mask_has_no_ends():
    m = _polyline_mask([(10, 10), (90, 10)]) | _polyline_mask([(10, 60), (30, 60)])
    ends = geodesic_ends(MaskView(m))
    assert sorted(round(p[0] / 10) for p in ends) == [1, 9]
    assert all(abs(p[1] - 10) <= 2 for p in ends)
    assert geodesic_ends(MaskView(np.zeros((20, 20), bool))) is None
