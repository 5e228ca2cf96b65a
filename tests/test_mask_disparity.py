"""Mask disparity: the shift that overlays the two eyes' needle masks, sub-pixel, or None."""

import cv2
import numpy as np

from suture_bt.perception.mask_disparity import mask_disparity
from suture_bt.perception.pose_fit import MaskView


def _arc_mask(shift: float = 0.0) -> np.ndarray:
    m = np.zeros((300, 400), np.uint8)
    centre = (int(round(200 * 16 - shift * 16)), 150 * 16)
    cv2.ellipse(m, centre, (80 * 16, 50 * 16), 20, 0, 130, 1, 5, cv2.LINE_8, 4)
    return m.astype(bool)


def test_shift_between_crops_is_recovered():
    left = _arc_mask()
    right = _arc_mask(23.0)
    L = MaskView(left[100:250, 100:320], (100, 100))
    R = MaskView(right[90:260, 60:300], (60, 90))  # a different crop of the right image
    assert abs(mask_disparity(L, R, 5, 60) - 23.0) < 0.5


def test_sub_pixel_shift():
    d = mask_disparity(MaskView(_arc_mask()), MaskView(_arc_mask(17.5)), 5, 60)
    assert abs(d - 17.5) < 0.5


def test_empty_or_unrelated_masks_give_none():
    left = MaskView(_arc_mask())
    assert mask_disparity(left, MaskView(np.zeros((300, 400), bool)), 5, 60) is None
    far = np.zeros((300, 400), bool)
    far[10:14, 10:20] = True  # a speck nowhere near the arc at any allowed shift
    assert mask_disparity(left, MaskView(far), 5, 60) is None
