"""The answer gates: one frozen object whose defaults are the documented limits, whose angle
limit follows the priors, and which a caller loosens for one call without changing the
localiser's own."""

from dataclasses import FrozenInstanceError, replace

import numpy as np
import pytest

from suture_bt.perception import (
    answer_gates,
    exposure_gate,
    rival_probe,
    short_tie,
    spread_limits,
)
from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.needle_prior import HeldPrior, PortPrior


def test_defaults_are_the_documented_limits():
    g = AnswerGates()
    assert g.max_rms_px == answer_gates.MAX_RMS_PX
    assert g.min_inlier_fraction == answer_gates.MIN_INLIER_FRACTION
    assert g.max_position_std_mm == answer_gates.MAX_POSITION_STD_MM
    assert g.refit_moved_px == answer_gates.REFIT_MOVED_PX
    assert g.max_rival_ratio == rival_probe.MAX_RIVAL_RATIO
    assert g.max_tie_ratio == rival_probe.MAX_TIE_RATIO
    assert g.max_tie_ratio_far == rival_probe.MAX_TIE_RATIO_FAR
    assert g.far_tie_depth == rival_probe.FAR_TIE_DEPTH
    assert g.max_tie_ratio_short == short_tie.MAX_TIE_RATIO_SHORT
    assert g.short_seen == short_tie.SHORT_SEEN
    assert g.max_angle_std_deg == spread_limits.MAX_ANGLE_STD_DEG
    assert g.max_angle_std_deg_held == spread_limits.MAX_ANGLE_STD_DEG_HELD
    assert g.max_angle_std_deg_in_tissue == spread_limits.MAX_ANGLE_STD_DEG_IN_TISSUE
    assert g.max_exposed == exposure_gate.MAX_EXPOSED


def test_the_angle_limit_follows_the_priors_and_the_gates_own_values():
    port = PortPrior("entry 1", np.zeros(3), 0.002)
    pinned = HeldPrior("psm2", np.zeros(3), spread_limits.HELD_PIN_TOLERANCE)
    g = AnswerGates(max_angle_std_deg=3.0, max_angle_std_deg_held=5.0)
    unaided = 3.0 * spread_limits.MAX_ANGLE_STD_DEG_UNAIDED / spread_limits.MAX_ANGLE_STD_DEG
    assert g.angle_std_limit(()) == pytest.approx(unaided)
    assert g.angle_std_limit((port,)) == 3.0
    assert g.angle_std_limit((pinned,)) == 5.0


def test_a_far_answer_without_priors_is_held_to_the_far_tie_limit():
    g = AnswerGates()
    assert rival_probe.MAX_TIE_RATIO < rival_probe.MAX_TIE_RATIO_FAR
    near = rival_probe.FAR_TIE_DEPTH - 0.005
    assert g.tie_limit(near, ()) == rival_probe.MAX_TIE_RATIO
    assert g.tie_limit(rival_probe.FAR_TIE_DEPTH, ()) == rival_probe.MAX_TIE_RATIO_FAR
    assert g.tie_limit(0.2, ()) == rival_probe.MAX_TIE_RATIO_FAR
    # A prior has chosen the candidates weighed: the near limit holds at any depth.
    port = PortPrior("entry 1", np.zeros(3), 0.002)
    assert g.tie_limit(0.2, (port,)) == rival_probe.MAX_TIE_RATIO
    # The caller's own values, far and near.
    loose = AnswerGates(max_tie_ratio=0.5, max_tie_ratio_far=0.7, far_tie_depth=0.1)
    assert (loose.tie_limit(0.09, ()), loose.tie_limit(0.1, ())) == (0.5, 0.7)


def test_a_short_near_view_without_priors_is_held_to_the_short_tie_limit():
    g = AnswerGates()
    short, seen_whole, near = short_tie.SHORT_SEEN - 0.001, 0.02, g.far_tie_depth - 0.02
    assert g.short_tie_limit(short, near, ()) == short_tie.MAX_TIE_RATIO_SHORT
    # Seen long enough, far (the far limit's), or with a prior: no limit here (0).
    assert g.short_tie_limit(seen_whole, near, ()) == 0.0
    assert g.short_tie_limit(short, g.far_tie_depth, ()) == 0.0
    port = PortPrior("entry 1", np.zeros(3), 0.002)
    assert g.short_tie_limit(short, near, (port,)) == 0.0
    # The caller's own values; a caller that turns the tie gates off sets this one too.
    own = AnswerGates(max_tie_ratio_short=1.5, short_seen=0.01, far_tie_depth=0.1)
    assert own.short_tie_limit(0.009, 0.09, ()) == 1.5
    assert own.short_tie_limit(0.011, 0.09, ()) == 0.0


def test_gates_are_frozen_so_loosening_one_call_cannot_leak_into_the_next():
    g = AnswerGates()
    with pytest.raises(FrozenInstanceError):
        g.max_rms_px = 1.0  # type: ignore[misc]
    loose = replace(g, max_rms_px=1.0)
    assert loose.max_rms_px == 1.0 and g.max_rms_px == answer_gates.MAX_RMS_PX
