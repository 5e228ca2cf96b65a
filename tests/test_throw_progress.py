"""A retried throw skips what it has done (behaviours/throw_progress.py), and a RecoveryNode
that blames its recovery reports the recovery's reason (no simulation)."""

from types import SimpleNamespace

import numpy as np
import py_trees
from py_trees.behaviours import StatusQueue
from py_trees.common import Status

from suture_bt.behaviours.recovery import RecoveryNode
from suture_bt.behaviours.throw_progress import (
    SkipWhen,
    grasp_leaves_room,
    grasp_reaches,
    holds_needle,
    pulled_through,
)
from suture_bt.behaviours.throw_scope import failure_reason
from suture_bt.skills.context import NeedleBelief

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class Said(StatusQueue):
    """A StatusQueue whose feedback is fixed (what it would say on failure)."""

    def __init__(self, name, queue, says=""):
        super().__init__(name, list(queue), queue[-1])
        self.says = says
        self.ticks = 0

    def update(self) -> Status:
        self.ticks += 1
        self.feedback_message = self.says
        return super().update()


def _ctx(reports=(), t_start=10.0, belief=None):
    return SimpleNamespace(reports=list(reports), throws={1: {"t_start": t_start}}, belief=belief)


def test_pulled_through_reads_this_throws_own_extraction_reports():
    ok = {"skill": "extract", "status": "SUCCESS", "t_start": 12.0, "t_end": 15.0}
    assert pulled_through(_ctx([ok]), 1) == "pair 1 pulled through at t = 15.0 s"
    assert pulled_through(_ctx([ok | {"status": "FAILURE"}]), 1) == ""
    assert pulled_through(_ctx([ok | {"t_start": 5.0}]), 1) == ""  # an earlier throw's
    assert pulled_through(_ctx([ok]), 2) == ""  # throw 2 has not started


def test_holds_needle_needs_the_arm_and_its_in_hand_pose():
    held = NeedleBelief(np.eye(4), 0.0, "vision", "psm2", np.eye(4))
    assert "psm2 already holds the needle" in holds_needle("psm2")(_ctx(belief=held))
    assert holds_needle("psm1")(_ctx(belief=held)) == ""
    free = NeedleBelief(np.eye(4), 0.0, "vision", None)
    assert holds_needle("psm2")(_ctx(belief=free)) == ""


def _tick(root, ctx, n=1):
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup(context=ctx)
    for _ in range(n):
        tree.tick()
    return tree


def test_skip_when_done_never_ticks_the_child():
    child = Said("work", [R, S])
    skip = SkipWhen("Unless done", child, lambda c: "done before")
    _tick(skip, _ctx())
    assert skip.status == S and skip.skipped and child.ticks == 0
    assert skip.feedback_message == "skipped: done before"


def test_skip_when_not_done_is_the_child():
    child = Said("work", [R, F], says="it broke")
    skip = SkipWhen("Unless done", child, lambda c: "")
    _tick(skip, _ctx(), 2)
    assert skip.status == F and not skip.skipped and child.ticks == 2
    assert skip.feedback_message == "it broke"


def _blaming(guard_says_yes: bool):
    action = Said("attempt", [F], says="needle dropped by psm2")
    guard = Said("Needle dropped?", [S if guard_says_yes else F], says="guard's answer")
    step = Said("Find it", [F], says="needle dropped by psm2 and out of both arms' reach")
    recovery = py_trees.composites.Sequence("recover", memory=True, children=[guard, step])
    node = RecoveryNode("retry", action, recovery, 1, blame_recovery=True)
    _tick(node, _ctx())
    return node, action


def test_a_recovery_that_applied_and_failed_is_the_reason():
    node, action = _blaming(True)
    assert node.status == F and action.status == Status.INVALID
    assert [h[1:3] for h in node.history] == [("attempt", F), ("recover", F)]
    assert "the attempt failed: needle dropped by psm2" in node.feedback_message
    assert failure_reason(node) == ("Find it: needle dropped by psm2 and out of both arms' reach")


def test_a_recovery_whose_guard_refused_leaves_the_attempts_reason():
    node, action = _blaming(False)
    assert node.status == F and action.status == F
    assert failure_reason(node) == "attempt: needle dropped by psm2"


def test_grasp_leaves_room_reads_the_planners_grasp_limit():
    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.planning import plan_needle_arc
    from suture_bt.skills.grasps import hand, insertion_grasp_angle

    phantom, needle = PhantomModel(), NeedleModel()
    good = insertion_grasp_angle(plan_needle_arc(*phantom.pair(1), needle))

    def ctx(angle):
        held = NeedleBelief(np.eye(4), 0.0, "vision", "psm2", hand(needle, angle))
        return SimpleNamespace(phantom=phantom, needle=needle, belief=held)

    check = grasp_leaves_room(1, "psm2")
    assert check(ctx(good)) == "psm2's grasp leaves the tip room for pair 1"
    assert check(ctx(good - np.deg2rad(22.0))) == ""  # slid 4 mm toward the tip: re-grasp
    assert "not known to hold" in grasp_leaves_room(1, "psm1")(ctx(good))


def test_grasp_reaches_says_when_the_held_needle_cannot_be_brought_to_the_approach():
    from skill_helpers import make_arm

    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.planning import plan_needle_arc
    from suture_bt.skills.grasps import hand, insertion_grasp_angle
    from suture_bt.skills.resting_grasp import turned_over_hand

    phantom, needle = PhantomModel(), NeedleModel()
    angle = insertion_grasp_angle(plan_needle_arc(*phantom.pair(1), needle))
    arm = make_arm("psm2")

    def ctx(T_tip_needle):
        held = NeedleBelief(np.eye(4), 0.0, "vision", "psm2", T_tip_needle)
        return SimpleNamespace(phantom=phantom, needle=needle, belief=held, arm=lambda name: arm)

    check = grasp_reaches(1, "psm2")
    assert check(ctx(hand(needle, angle))) == "psm2's grasp reaches pair 1's approach"
    # Picked up lying turned over (a needle that flipped when laid down): the wrist cannot
    # turn the needle to the entry; the tree re-grasps through PSM1.
    assert check(ctx(turned_over_hand(needle, angle))) == ""
    assert "not known to hold" in grasp_reaches(1, "psm1")(ctx(hand(needle, angle)))


def test_the_reason_of_a_failed_either_or_is_the_chosen_options_not_the_other_guard():
    import operator

    from py_trees.common import ComparisonExpression

    py_trees.blackboard.Blackboard.clear()
    writer = py_trees.blackboard.Client(name="test")
    writer.register_key("/start", access=py_trees.common.Access.WRITE)
    writer.set("/start", "tissue")
    picked = Said("Pick up", [F], "needle not localised: the network sees no needle")
    choose = py_trees.idioms.either_or(
        conditions=[
            ComparisonExpression("/start", "jaw", operator.eq),
            ComparisonExpression("/start", "tissue", operator.eq),
        ],
        subtrees=[Said("From the jaw", [S]), picked],
        name="Where is the needle?",
    )
    tree = py_trees.trees.BehaviourTree(choose)
    tree.tick()
    assert choose.status == F
    assert failure_reason(choose) == "Pick up: needle not localised: the network sees no needle"
    py_trees.blackboard.Blackboard.clear()
