"""The wire's thickness in a mask: the ridge's median distance to the edge is the wire's half
width (plus a small bias), a blob beside the wire barely moves it, and it tells which of two
depths a mask agrees with."""

import cv2
import numpy as np

from suture_bt.perception.wire_width import (
    RIDGE_BIAS_PX,
    WIDTH_AGREEMENT,
    ridge_half_width,
    thin_for,
    width_ratio,
)

RADIUS, FX = 0.36e-3, 789.3


def _wire(half_width: int, blob: bool = False) -> np.ndarray:
    """A curved wire of the given half width (px), with a 30 px blob touching it."""
    m = np.zeros((300, 400), np.uint8)
    cv2.ellipse(m, (200, 250), (150, 150), 0, 200, 330, 1, thickness=2 * half_width + 1)
    if blob:
        cv2.circle(m, (75, 200), 15, 1, -1)
    return m.astype(bool)


def test_the_ridge_measures_the_wires_half_width():
    """To within the ±30 % the depth rule allows (a band 2·hw + 1 px across: hw + 0.5)."""
    for hw in (2, 3, 5):
        w = ridge_half_width(_wire(hw)) - RIDGE_BIAS_PX
        assert 1.0 <= w / (hw + 0.5) <= 1.3
    assert ridge_half_width(np.zeros((10, 10), bool)) is None


def test_a_blob_beside_the_wire_barely_moves_the_median():
    assert abs(ridge_half_width(_wire(3, blob=True)) - ridge_half_width(_wire(3))) < 0.5


def test_width_ratio_is_one_for_a_wire_at_that_depth():
    z = 0.09
    hw = RADIUS * FX / z
    assert np.isclose(width_ratio(hw + RIDGE_BIAS_PX, RADIUS, FX, z), 1.0)


def test_thin_for_names_the_depth_the_wire_agrees_with():
    """A wire 3 px in half width is a wire about 95 mm away, far too thin for 35 mm."""
    masks = [_wire(3, blob=True), _wire(3)]
    assert thin_for(masks, 0.095, 0.035, RADIUS, FX)
    assert not thin_for(masks, 0.035, 0.095, RADIUS, FX)  # thick enough for neither rule
    # Two depths the width cannot tell apart: no verdict.
    assert not thin_for(masks, 0.095, 0.095 * WIDTH_AGREEMENT**-0.5, RADIUS, FX)
    assert not thin_for([np.zeros((5, 5), bool)], 0.095, 0.035, RADIUS, FX)
