"""In-hand check before an insertion: what one look says about a drift of the calibrated arm
(the second look that must agree is exercised in the full tree, test_recovery_branches)."""

import numpy as np
from skill_helpers import make_arm, make_ctx

from suture_bt.skills.grasps import hand
from suture_bt.skills.in_hand_check import DRIFT_JAW, DRIFT_POSITION, CheckInHand
from suture_bt.transforms import make_transform


def _check():
    ctx = make_ctx()
    arm = make_arm("psm2")
    arm.calibrated = True
    ctx.arms = {"psm2": arm}
    predicted = arm.tip_world() @ hand(ctx.needle, np.deg2rad(150.0))
    return CheckInHand(ctx, "psm2", 1), arm, predicted


def test_a_needle_where_its_grasp_says_is_no_drift():
    check, arm, predicted = _check()
    assert check._drift_seen(arm, predicted, predicted) == ""
    near = predicted.copy()
    near[:3, 3] += 0.5 * DRIFT_POSITION  # a look's own error
    assert check._drift_seen(arm, near, predicted) == ""


def test_a_needle_moved_with_the_jaw_is_a_drift_and_an_uncalibrated_arm_never_drifts():
    check, arm, predicted = _check()
    moved = make_transform(None, (0.002, 0.0, 0.0)) @ predicted  # 2 mm, no turn: with the jaw
    why = check._drift_seen(arm, moved, predicted, record=True)
    assert "from its pinch point" in why
    assert check.report["off_prediction_mm"] > 1e3 * DRIFT_POSITION
    assert check.report["jaw_distance_mm"] > 1e3 * DRIFT_JAW
    arm.calibrated = False
    assert check._drift_seen(arm, moved, predicted) == ""
