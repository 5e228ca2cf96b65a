"""SimTimeout: py_trees' Timeout in simulated time (behaviours/sim_timeout.py)."""

import time

import py_trees
import pytest
from py_trees.behaviours import Running, StatusQueue
from py_trees.common import Status

from suture_bt.behaviours.sim_timeout import SimTimeout


class FakeClock:
    """Simulated time that moves only when the test says so."""

    def __init__(self, t: float = 10.0):
        self.t = t

    def now(self) -> float:
        return self.t


class Talking(StatusQueue):
    """A StatusQueue that says what it is doing."""

    steps = 0

    def update(self) -> Status:
        self.steps += 1
        self.feedback_message = f"{self.name} step {self.steps}"
        return super().update()


@pytest.fixture(autouse=True)
def _clean_blackboard():
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()


def _tree(child, duration=2.0, clock=None):
    clock = clock or FakeClock()
    root = SimTimeout("timeout", child, duration)
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup(clock=clock)
    return tree, root, clock


def test_times_out_in_simulated_time_and_stops_the_child():
    child = Talking("move", [Status.RUNNING], eventually=Status.RUNNING)
    tree, root, clock = _tree(child, duration=2.0)
    tree.tick()
    assert root.status == Status.RUNNING and root.feedback_message == "move step 1"
    clock.t += 2.0  # exactly the duration: not yet
    tree.tick()
    assert root.status == Status.RUNNING and root.elapsed == pytest.approx(2.0)
    clock.t += 0.01
    tree.tick()
    assert root.status == Status.FAILURE
    assert child.status == Status.INVALID
    assert root.feedback_message.startswith("timed out after 2.0 s of simulated time")
    assert "'move' was still running: move step 3" in root.feedback_message


def test_mirrors_the_child_that_finishes_in_time():
    for final in (Status.SUCCESS, Status.FAILURE):
        child = Talking("grasp", [Status.RUNNING, final], eventually=None)
        tree, root, clock = _tree(child, duration=1.0)
        tree.tick()
        clock.t += 0.5
        tree.tick()
        assert root.status == final and child.status == final
        assert root.feedback_message == "grasp step 2"


def test_a_child_finishing_on_the_last_tick_keeps_its_result():
    child = StatusQueue("late", [Status.RUNNING, Status.SUCCESS], eventually=None)
    tree, root, clock = _tree(child, duration=1.0)
    tree.tick()
    clock.t += 5.0
    tree.tick()
    assert root.status == Status.SUCCESS  # as py_trees' Timeout: finished before timeout


def test_restarts_the_clock_on_every_run():
    child = Running("wait")
    tree, root, clock = _tree(child, duration=1.0)
    tree.tick()
    clock.t += 1.5
    tree.tick()
    assert root.status == Status.FAILURE
    tree.tick()  # a fresh run starts at the current simulated time
    assert root.status == Status.RUNNING and root.start_time == clock.t
    clock.t += 0.9
    tree.tick()
    assert root.status == Status.RUNNING


def test_zero_duration_allows_exactly_the_first_tick():
    tree, root, clock = _tree(Running("r"), duration=0.0)
    tree.tick()
    assert root.status == Status.RUNNING
    clock.t += 1e-3
    tree.tick()
    assert root.status == Status.FAILURE


def test_pausing_in_wall_time_changes_nothing(monkeypatch):
    sim_tree, sim, clock = _tree(Talking("a", [Status.RUNNING], Status.RUNNING), duration=1.0)
    wall = py_trees.decorators.Timeout("wall", Running("b"), duration=1.0)
    wall_tree = py_trees.trees.BehaviourTree(wall)
    wall_tree.setup()
    for tree in (sim_tree, wall_tree):
        tree.tick()
    # A debugger session of an hour between two ticks: simulated time did not move.
    later = time.monotonic() + 3600.0
    monkeypatch.setattr(time, "monotonic", lambda: later)
    monkeypatch.setattr(time, "time", lambda: later)
    for tree in (sim_tree, wall_tree):
        tree.tick()
    assert sim.status == Status.RUNNING and sim.elapsed == 0.0
    assert sim.feedback_message == "a step 2"
    assert wall.status == Status.FAILURE  # what py_trees' own Timeout does, for contrast


def test_pre_emption_stops_the_child():
    child = Running("r")
    tree, root, clock = _tree(child)
    tree.tick()
    root.stop(Status.INVALID)
    assert root.status == Status.INVALID and child.status == Status.INVALID


def test_setup_without_a_clock_is_a_clear_error():
    root = SimTimeout("approach timeout", Running("r"), 3.0)
    with pytest.raises(RuntimeError, match=r"SimTimeout 'approach timeout' needs setup\(clock"):
        py_trees.trees.BehaviourTree(root).setup()
    with pytest.raises(RuntimeError, match="needs setup"):
        root.setup(clock=object())
    with pytest.raises(RuntimeError, match="before ticking"):
        root.tick_once()


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "2"])
def test_duration_must_be_a_finite_non_negative_time(bad):
    with pytest.raises(ValueError, match="duration"):
        SimTimeout("t", Running("r"), bad)
