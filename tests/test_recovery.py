"""RecoveryNode: Nav2's recovery composite for py_trees (behaviours/recovery.py)."""

import py_trees
import pytest
from py_trees.behaviours import StatusQueue
from py_trees.common import Status

from suture_bt.behaviours.recovery import RecoveryNode, recovery_idiom

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class Scripted(StatusQueue):
    """A StatusQueue that says what it returns and remembers how it was ticked and stopped."""

    def __init__(self, name, queue, eventually=None):
        super().__init__(name, list(queue), eventually)
        self.ticks = 0
        self.initialised = 0
        self.terminated: list[Status] = []

    def initialise(self) -> None:
        self.initialised += 1

    def update(self) -> Status:
        status = super().update()
        self.ticks += 1
        self.feedback_message = f"{self.name} {status.name.lower()} #{self.ticks}"
        return status

    def terminate(self, new_status: Status) -> None:
        self.terminated.append(new_status)


@pytest.fixture(autouse=True)
def _clean_blackboard():
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()


def _tree(action_q, recovery_q, num_retries=2, action_eventually=None, recovery_eventually=None):
    action = Scripted("action", action_q, action_eventually)
    recovery = Scripted("recovery", recovery_q, recovery_eventually)
    node = RecoveryNode("recover", action, recovery, num_retries)
    tree = py_trees.trees.BehaviourTree(node)
    tree.setup()
    return tree, node, action, recovery


def test_success_on_the_first_attempt():
    tree, node, action, recovery = _tree([R, S], [S])
    tree.tick()
    assert node.status == R and node.feedback_message == "attempt 1 of 3: action running #1"
    assert tree.tip() is action and node.current_child is action
    tree.tick()
    assert node.status == S and node.attempts == 1 and node.retries == 0
    assert node.feedback_message == "succeeded on attempt 1 of 3: action success #2"
    assert recovery.ticks == 0 and recovery.status == Status.INVALID
    assert node.history == [(1, "action", S, "action success #2")]


def test_recovery_then_success_on_the_next_attempt():
    tree, node, action, recovery = _tree([R, F, S], [R, S])
    tree.tick()
    tree.tick()  # the action fails; the recovery starts on the same tick
    assert node.status == R and node.current_child is recovery and tree.tip() is recovery
    assert action.status == F  # the failure stays visible while the recovery runs
    assert node.feedback_message == (
        "attempt 1 of 3 failed: action failure #2; recovering: recovery running #1"
    )
    tree.tick()  # the recovery succeeds: the action runs again on the next tick
    assert node.status == R and node.retries == 1 and node.attempts == 1
    assert node.feedback_message == (
        "attempt 1 of 3 failed: action failure #2; recovered (recovery success #2), "
        "attempt 2 of 3 next"
    )
    tree.tick()
    assert node.status == S and node.attempts == 2
    assert node.feedback_message == "succeeded on attempt 2 of 3: action success #3"
    assert recovery.status == Status.INVALID  # reset before the new attempt
    # The action was reset (stopped to INVALID) between attempts and initialised afresh.
    assert action.terminated == [F, Status.INVALID, S] and action.initialised == 2
    assert recovery.terminated == [S, Status.INVALID]
    assert node.history == [
        (1, "action", F, "action failure #2"),
        (1, "recovery", S, "recovery success #2"),
        (2, "action", S, "action success #3"),
    ]


def test_a_failed_recovery_fails_with_both_reasons():
    tree, node, action, recovery = _tree([F], [F])
    tree.tick()
    assert node.status == F and action.ticks == 1 and recovery.ticks == 1
    assert node.feedback_message == (
        "recovery 'recovery' failed after attempt 1 of 3: recovery failure #1 "
        "(the attempt failed: action failure #1)"
    )
    assert [h[1:3] for h in node.history] == [("action", F), ("recovery", F)]
    assert tree.tip() is recovery  # the last child that ran, as a Selector keeps it


def test_retries_exhausted_gives_up_with_the_last_reason():
    tree, node, action, recovery = _tree([], [], 2, action_eventually=F, recovery_eventually=S)
    statuses = []
    for _ in range(3):
        tree.tick()
        statuses.append(node.status)
    assert statuses == [R, R, F]
    assert action.ticks == 3 and recovery.ticks == 2
    assert node.attempts == 3 and node.retries == 2
    assert node.feedback_message == "gave up after 3 attempts: action failure #3"
    assert [(a, name) for a, name, *_ in node.history] == [
        (1, "action"),
        (1, "recovery"),
        (2, "action"),
        (2, "recovery"),
        (3, "action"),
    ]


def test_no_retries_fails_at_once():
    tree, node, action, recovery = _tree([F], [S], num_retries=0)
    tree.tick()
    assert node.status == F and recovery.ticks == 0
    assert node.feedback_message == "gave up after 1 attempt: action failure #1"


def test_a_silent_failure_is_still_named():
    node = RecoveryNode("r", StatusQueue("grasp", [F], None), StatusQueue("x", [S], None), 0)
    node.tick_once()
    assert node.feedback_message == "gave up after 1 attempt: 'grasp' gave no reason"


def test_clean_restart_when_ticked_again_after_finishing():
    tree, node, action, recovery = _tree([F, F], [F], recovery_eventually=R)
    tree.tick()
    assert node.status == F
    old_history = node.history
    tree.tick()  # a new run: first attempt, fresh history, children reset first
    assert node.status == R and node.attempts == 1 and node.retries == 0
    assert action.status == F and recovery.status == R
    assert len(old_history) == 2 and node.history == [(1, "action", F, "action failure #2")]
    assert recovery.terminated == [F, Status.INVALID]


def test_pre_empted_mid_recovery():
    tree, node, action, recovery = _tree([F], [R], recovery_eventually=R)
    tree.tick()
    assert recovery.status == R
    node.stop(Status.INVALID)
    assert node.status == action.status == recovery.status == Status.INVALID
    assert recovery.terminated == [Status.INVALID]
    assert node.current_child is None and node.tip() is None
    assert node.history[-1] == (1, "recovery", Status.INVALID, "recovery running #1")


def test_pre_empted_by_a_higher_priority_branch_and_resumed_afresh():
    guard = StatusQueue("guard", [F, F, S, F], None)
    action = Scripted("action", [F, R], R)
    recovery = Scripted("recovery", [S], S)
    node = recovery_idiom("recover", action, recovery, 2)
    root = py_trees.composites.Selector("root", memory=False, children=[guard, node])
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    tree.tick()  # action fails, recovery succeeds
    tree.tick()  # attempt 2 running
    assert node.attempts == 2 and action.status == R and tree.tip() is action
    tree.tick()  # the guard wins: the RecoveryNode and its running action are stopped
    assert node.status == action.status == Status.INVALID
    assert action.terminated[-1] == Status.INVALID
    tree.tick()
    assert node.status == R and node.attempts == 1  # a fresh run


def test_the_display_shows_the_running_child():
    tree, node, action, recovery = _tree([F], [R], recovery_eventually=R)
    snapshot = py_trees.visitors.SnapshotVisitor()
    tree.add_visitor(snapshot)
    tree.tick()
    assert snapshot.visited[recovery.id] == R and snapshot.visited[action.id] == F
    text = py_trees.display.unicode_tree(tree.root, show_status=True, visited=snapshot.visited)
    assert "attempt 1 of 3 failed: action failure #1; recovering" in text
    assert "recovery [*] -- recovery running #1" in text


def test_exactly_two_children_and_valid_retries():
    a, b = StatusQueue("a", [S], None), StatusQueue("b", [S], None)
    node = RecoveryNode("r", a, b, 1)
    assert (node.action, node.recovery, node.max_attempts) == (a, b, 2)
    with pytest.raises(RuntimeError, match="exactly two children"):
        node.add_child(StatusQueue("c", [S], None))
    with pytest.raises(ValueError, match="num_retries"):
        RecoveryNode("r", StatusQueue("a", [S], None), StatusQueue("b", [S], None), -1)
    with pytest.raises(ValueError, match="num_retries"):
        RecoveryNode("r", StatusQueue("a", [S], None), StatusQueue("b", [S], None), 1.5)
    c = StatusQueue("c", [S], None)
    with pytest.raises(ValueError, match="two nodes"):
        RecoveryNode("r", c, c, 1)
    node.remove_child(b)
    with pytest.raises(RuntimeError, match="needs exactly two children"):
        node.tick_once()


def test_recovery_idiom_returns_the_node():
    a, b = StatusQueue("a", [S], None), StatusQueue("b", [S], None)
    node = recovery_idiom("grasp with regrasp", a, b, 3)
    assert isinstance(node, RecoveryNode) and isinstance(node, py_trees.composites.Composite)
    assert node.name == "grasp with regrasp" and node.children == [a, b]
    assert a.parent is node and b.parent is node and node.num_retries == 3
