"""The task priors of a held needle: the pinch tolerance by calibration, the held face by
belief."""

from types import SimpleNamespace

import numpy as np

from suture_bt.skills.held_priors import (
    ACROSS_JAWS_DEG,
    ACROSS_JAWS_DEG_CALIBRATED,
    HOLD_TOLERANCE_CALIBRATED,
    PINCH_TO_BLADE_END,
    held_priors,
    hold_tolerance,
)
from suture_bt.transforms import make_transform

TIP = make_transform(np.eye(3), (0.01, 0.02, 0.1))
Q = np.array([0.2, -0.1, 0.12, 0.0, 0.0, 0.0])


def _ctx(calibrated: bool, belief=None):
    arm = SimpleNamespace(
        name="psm2",
        calibrated=calibrated,
        tip_world=lambda: TIP.copy(),
        servo=SimpleNamespace(estimated_jp=lambda: Q.copy()),
    )
    return SimpleNamespace(arm=lambda name: arm, belief=belief)


def test_a_calibrated_holder_gives_the_tight_pinch_and_the_calibrated_jaw_limit():
    kw = held_priors(_ctx(True), "psm2")
    assert kw["holder"][0] == "psm2"
    np.testing.assert_array_equal(kw["holder"][1], TIP)
    assert kw["holder_tolerance"] == HOLD_TOLERANCE_CALIBRATED + PINCH_TO_BLADE_END
    assert kw["jaw_tolerance_deg"] == ACROSS_JAWS_DEG_CALIBRATED
    np.testing.assert_allclose(kw["held_face"], -TIP[:3, 2])  # against the tip's z axis


def test_an_uncalibrated_holder_widens_the_pinch_by_its_worst_hidden_offset():
    ctx = _ctx(False)
    assert hold_tolerance(ctx.arm("psm2")) > 2 * HOLD_TOLERANCE_CALIBRATED
    assert held_priors(ctx, "psm2")["jaw_tolerance_deg"] == ACROSS_JAWS_DEG


def test_the_belief_of_a_needle_held_turned_over_sets_the_face():
    turned_over = make_transform(np.eye(3), (0.0, 0.0, 0.01))  # needle z along the tip's
    belief = SimpleNamespace(holder="psm2", T_tip_needle=turned_over)
    kw = held_priors(_ctx(True, belief), "psm2")
    np.testing.assert_allclose(kw["held_face"], TIP[:3, 2])
