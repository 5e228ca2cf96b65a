"""``Parallel`` that says why: py_trees' Parallel leaves ``feedback_message`` empty, so a
recovery node above it would log "gave no reason"; this one carries its children's words."""

from __future__ import annotations

from collections.abc import Iterator

import py_trees
from py_trees.behaviour import Behaviour
from py_trees.common import Status

from suture_bt.behaviours.throw_scope import failure_reason


class ParallelWithReason(py_trees.composites.Parallel):
    """A Parallel whose feedback is a failed child's (``name: feedback``), else the feedback
    of child ``voice`` (the one doing the work)."""

    def __init__(self, name: str, policy, children: list[Behaviour], voice: int = 0):
        super().__init__(name, policy=policy, children=children)
        self.voice = voice

    def tick(self) -> Iterator[Behaviour]:
        """Tick as a Parallel, then say what the children said."""
        for node in super().tick():
            if node is self:
                self.feedback_message = self._said()
            yield node

    def _said(self) -> str:
        for child in self.children:
            if child.status == Status.FAILURE:
                if child.feedback_message:
                    return f"{child.name}: {child.feedback_message}"
                return f"{child.name}: {failure_reason(child)}"  # a composite says nothing
        return self.children[self.voice].feedback_message if self.children else ""
