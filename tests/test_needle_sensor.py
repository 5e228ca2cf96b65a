"""The needle sensor's working range: a needle nearer the cameras than the localiser's floor."""

import numpy as np
from skill_helpers import CAMERA

from suture_bt.perception.needle_localizer import MIN_DEPTH
from suture_bt.skills.needle_sensor import RANGE_MARGIN, in_working_range


def _at_depth(depth: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (CAMERA.model.left.T_world_cam @ np.array([0.0, 0.0, depth, 1.0]))[:3]
    return T


def test_a_needle_nearer_than_the_localisers_floor_is_out_of_range():
    assert not in_working_range(CAMERA, _at_depth(0.015))
    assert in_working_range(CAMERA, _at_depth(0.028))  # the in-hand check's risen view
    assert not in_working_range(CAMERA, _at_depth(MIN_DEPTH))
    assert in_working_range(CAMERA, _at_depth(MIN_DEPTH + RANGE_MARGIN + 1e-4))
    assert in_working_range(CAMERA, _at_depth(0.12))


def test_an_unknown_needle_is_worth_a_look():
    assert in_working_range(CAMERA, None)
