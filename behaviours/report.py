"""``SutureReport``: the last node of a suture tree; sums up what the tree believes of its throws.

The scores that count come from the world's records after the run (the runtime), not from
here: this node reports the tree's own view, so the two can be compared.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from suture_bt.behaviours.skill_behaviour import needs


class SutureReport(py_trees.behaviour.Behaviour):
    """SUCCESS when every throw of ``pairs`` ended in SUCCESS, else FAILURE, with a summary."""

    def __init__(self, pairs: tuple[int, ...], name: str = "Report"):
        super().__init__(name)
        self.pairs = tuple(pairs)
        self.context = None

    def setup(self, **kwargs) -> None:
        self.context = needs(kwargs, "context", f"behaviour {self.name!r}")

    def update(self) -> Status:
        throws = self.context.throws
        done = [p for p in self.pairs if throws.get(p, {}).get("status") == "SUCCESS"]
        self.feedback_message = f"{len(done)} of {len(self.pairs)} throws done by the tree's checks"
        return Status.SUCCESS if len(done) == len(self.pairs) else Status.FAILURE
