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


def test_needle_driven_in_pair_asks_the_free_needles_estimate():
    from suture_bt.behaviours.conditions import NeedleDrivenInPair, NeedleHangingInPair
    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.planning import plan_needle_arc
    from suture_bt.skills.context import NeedleBelief, TaskContext

    phantom, needle = PhantomModel(), NeedleModel()
    ctx = SimpleNamespace(phantom=phantom, needle=needle, belief=None)
    ctx.plan = lambda pair, where: TaskContext.plan(ctx, pair, where)
    arc = plan_needle_arc(*phantom.pair(2), needle)

    def ask(condition, T, holder=None):
        ctx.belief = None if T is None else NeedleBelief(T, 0.0, "vision", holder)
        condition.setup(context=ctx)
        condition.tick_once()
        return condition.status, condition.feedback_message

    part_way, pulled = arc.needle_pose(0.5), arc.needle_pose(arc.insert_end_angle + 0.2)
    assert ask(NeedleDrivenInPair(2), part_way)[0] == Status.SUCCESS
    assert ask(NeedleHangingInPair(2), part_way)[0] == Status.FAILURE  # tip not out
    assert ask(NeedleDrivenInPair(2), pulled)[0] == Status.FAILURE  # the puller's case
    assert ask(NeedleHangingInPair(2), pulled)[0] == Status.SUCCESS
    status, why = ask(NeedleDrivenInPair(2), part_way, holder="psm2")
    assert status == Status.FAILURE and "free needle" in why
    assert ask(NeedleDrivenInPair(2), None)[0] == Status.FAILURE
