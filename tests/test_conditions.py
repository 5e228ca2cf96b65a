"""Condition behaviours answer from the jaw's measured angle, and each can say no."""

from types import SimpleNamespace

import py_trees
import pytest
from py_trees.common import Status

from suture_bt.behaviours.conditions import JawEmpty, JawHoldsSomething
from suture_bt.skills.checks import JAW_ON_WIRE_MIN


@pytest.fixture(autouse=True)
def clean_blackboard():
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()


def _ask(condition, jaw_angle: float) -> tuple[Status, str]:
    arm = SimpleNamespace(jaw_angle=lambda: jaw_angle)
    condition.setup(context=SimpleNamespace(arm=lambda name: arm))
    condition.tick_once()
    return condition.status, condition.feedback_message


@pytest.mark.parametrize(
    "angle, holds",
    [(0.8, False), (JAW_ON_WIRE_MIN + 0.01, True), (0.0, False)],
    ids=["open", "on the wire", "closed empty"],
)
def test_jaw_holds_something_and_jaw_empty_say_opposite_things(angle, holds):
    held, why = _ask(JawHoldsSomething("psm2"), angle)
    empty, _ = _ask(JawEmpty("psm2"), angle)
    assert held == (Status.SUCCESS if holds else Status.FAILURE)
    assert empty == (Status.FAILURE if holds else Status.SUCCESS)
    assert why  # every answer says why
