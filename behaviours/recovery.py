"""``RecoveryNode``: Nav2's two-child recovery composite for py_trees.

py_trees has no equivalent: ``decorators.Retry`` retries its child but has no recovery step,
and a ``Selector`` of action and recovery never goes back to the action. Nav2's
RecoveryNode(number_of_retries) does: tick the action; if it fails and retries are left, tick
the recovery; if the recovery succeeds, run the action again; if the recovery fails, fail.

Every attempt is visible: ``feedback_message`` names the attempt and carries the running or
failing child's own feedback (that is how a failure's reason reaches the user), and
``history`` keeps each child's outcome of the current run.

``blame_recovery``: a recovery that applied (its guard, the first child of a composite
recovery, said yes) and then failed is the reason the node failed, not the attempt before it:
the failed action is reset (INVALID; its outcome stays in ``history`` and the feedback), so a
reader of the tree's failed nodes (``ThrowScope``) finds the recovery's reason first.
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import py_trees
from py_trees.behaviour import Behaviour
from py_trees.common import Status

#: One entry of :attr:`RecoveryNode.history`: (attempt, child name, status, feedback).
HistoryEntry = tuple[int, str, Status, str]


def _reason(child: Behaviour) -> str:
    return child.feedback_message or f"{child.name!r} gave no reason"


def _guard_passed(recovery: Behaviour) -> bool:
    """The recovery applied: a composite's first child (its guard) succeeded; a leaf always
    (decorators, such as a time limit, are looked through)."""
    while isinstance(recovery, py_trees.decorators.Decorator):
        recovery = recovery.decorated
    children = getattr(recovery, "children", [])
    return not children or children[0].status == Status.SUCCESS


def _said(prefix: str, child: Behaviour) -> str:
    """``prefix: <child's feedback>``, or just the prefix when the child says nothing."""
    return f"{prefix}: {child.feedback_message}" if child.feedback_message else prefix


class RecoveryNode(py_trees.composites.Composite):
    """Run ``action``; on failure run ``recovery`` and, if it succeeds, the action again.

    Up to ``num_retries`` recoveries, so the action runs at most ``num_retries + 1`` times
    (``max_attempts``). SUCCESS as soon as the action succeeds; FAILURE when a recovery fails
    or the action fails with no retries left. The action is re-run on the tick after its
    recovery succeeded, with both children reset (stopped to INVALID) first.

    Attributes:
        attempts: the action's current (or last) attempt, 1-based; 0 before the first tick
        retries: recoveries that succeeded in the current run
        history: (attempt, child name, status, feedback) of every child that finished in the
            current run (and of one pre-empted while running, with status INVALID)
    """

    def __init__(
        self,
        name: str,
        action: Behaviour,
        recovery: Behaviour,
        num_retries: int,
        blame_recovery: bool = False,
    ):
        if isinstance(num_retries, bool) or not isinstance(num_retries, int) or num_retries < 0:
            raise ValueError(f"RecoveryNode {name!r}: num_retries must be an int ≥ 0")
        if action is recovery:
            raise ValueError(f"RecoveryNode {name!r}: action and recovery must be two nodes")
        self.num_retries = num_retries
        self.blame_recovery = blame_recovery
        self.attempts = 0
        self.retries = 0
        self.history: list[HistoryEntry] = []
        self._retry_next_tick = False
        super().__init__(name, [action, recovery])

    # ---------------------------------------------------------------- children
    @property
    def action(self) -> Behaviour:
        return self.children[0]

    @property
    def recovery(self) -> Behaviour:
        return self.children[1]

    @property
    def max_attempts(self) -> int:
        return self.num_retries + 1

    def add_child(self, child: Behaviour) -> uuid.UUID:
        """Only two children, ever: the action, then the recovery."""
        if len(self.children) >= 2:
            raise RuntimeError(f"RecoveryNode {self.name!r} takes exactly two children")
        return super().add_child(child)

    # ---------------------------------------------------------------- tick
    def tick(self) -> Iterator[Behaviour]:
        """Tick the action or the recovery (see the class docstring)."""
        self.logger.debug(f"{self.__class__.__name__}.tick()")
        if len(self.children) != 2:
            raise RuntimeError(f"RecoveryNode {self.name!r} needs exactly two children")
        action, recovery = self.children
        if self.status != Status.RUNNING:
            self._start_afresh()
            self.initialise()
        elif self._retry_next_tick:
            self._retry_next_tick = False
            self._reset_children()
            self.attempts += 1
            self.current_child = action

        of = f"attempt {self.attempts} of {self.max_attempts}"
        if self.current_child is action:
            yield from action.tick()
            if action.status == Status.RUNNING:
                self.feedback_message = _said(of, action)
                self.status = Status.RUNNING
                yield self
                return
            self._record(action)
            if action.status == Status.SUCCESS:
                self.feedback_message = _said(f"succeeded on {of}", action)
                self.stop(Status.SUCCESS)
                yield self
                return
            if self.retries >= self.num_retries:
                n = self.attempts
                self.feedback_message = (
                    f"gave up after {n} attempt{'s' if n != 1 else ''}: {_reason(action)}"
                )
                self.stop(Status.FAILURE)
                yield self
                return
            if recovery.status != Status.INVALID:
                recovery.stop(Status.INVALID)
            self.current_child = recovery

        # The action failed with retries left: the recovery runs (on this same tick first).
        failed = f"{of} failed: {_reason(action)}"
        yield from recovery.tick()
        if recovery.status == Status.RUNNING:
            self.feedback_message = _said(f"{failed}; recovering", recovery)
            self.status = Status.RUNNING
        elif recovery.status == Status.SUCCESS:
            self._record(recovery)
            self.retries += 1
            self._retry_next_tick = True
            self.feedback_message = (
                f"{failed}; recovered ({recovery.feedback_message or recovery.name}), "
                f"attempt {self.attempts + 1} of {self.max_attempts} next"
            )
            self.status = Status.RUNNING
        else:
            self._record(recovery)
            self.feedback_message = (
                f"recovery {recovery.name!r} failed after {of}: {_reason(recovery)} "
                f"(the attempt failed: {_reason(action)})"
            )
            if self.blame_recovery and _guard_passed(recovery):
                action.stop(Status.INVALID)
            self.stop(Status.FAILURE)
        yield self

    def stop(self, new_status: Status = Status.INVALID) -> None:
        """Stop dangling children; a pre-emption (INVALID) is recorded in the history."""
        for child in self.children:
            if child.status == Status.RUNNING:
                if new_status == Status.INVALID:
                    entry = (self.attempts, child.name, Status.INVALID, child.feedback_message)
                    self.history.append(entry)
                child.stop(Status.INVALID)
        self._retry_next_tick = False
        super().stop(new_status)

    # ---------------------------------------------------------------- helpers
    def _start_afresh(self) -> None:
        """A new run: first attempt, fresh history (the old list is left to its readers)."""
        self._reset_children()
        self.attempts = 1
        self.retries = 0
        self.history = []
        self._retry_next_tick = False
        self.current_child = self.action

    def _reset_children(self) -> None:
        for child in self.children:
            if child.status != Status.INVALID:
                child.stop(Status.INVALID)

    def _record(self, child: Behaviour) -> None:
        self.history.append((self.attempts, child.name, child.status, child.feedback_message))


def recovery_idiom(
    name: str,
    action: Behaviour,
    recovery: Behaviour,
    num_retries: int,
    blame_recovery: bool = False,
) -> RecoveryNode:
    """The recovery pattern as a subtree factory, in the style of ``py_trees.idioms``."""
    return RecoveryNode(name, action, recovery, num_retries, blame_recovery)
