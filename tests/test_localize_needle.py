"""Localise-needle skill: an in-hand belief that the presentations keep refusing is dropped."""

from types import SimpleNamespace

import numpy as np

from suture_bt.skills.context import NeedleBelief
from suture_bt.skills.localize_needle import DOUBT_AFTER, LocalizeNeedle


def _skill(holder_of_belief: str | None) -> LocalizeNeedle:
    belief = None
    if holder_of_belief is not None:
        belief = NeedleBelief(np.eye(4), 0.0, "vision", holder_of_belief, np.eye(4))
    return LocalizeNeedle(SimpleNamespace(belief=belief), holder="psm2")


def test_in_hand_belief_is_dropped_after_refusals_in_a_row():
    skill = _skill("psm2")
    for refused in range(1, DOUBT_AFTER):
        assert not skill._doubt_belief(refused) and skill.context.belief is not None
    assert skill._doubt_belief(DOUBT_AFTER)
    assert skill.context.belief is None
    assert skill.report["belief_dropped_after"] == DOUBT_AFTER
    assert not skill._doubt_belief(DOUBT_AFTER + 1)  # nothing left to drop


def test_a_belief_about_another_holder_or_a_free_needle_is_kept():
    other = _skill("psm1")
    assert not other._doubt_belief(DOUBT_AFTER) and other.context.belief.holder == "psm1"
    free = _skill(None)
    assert not free._doubt_belief(DOUBT_AFTER) and free.context.belief is None
