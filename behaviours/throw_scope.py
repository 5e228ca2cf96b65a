"""``ThrowScope``: a decorator that marks one throw of the suture (its pair and time window).

It records when the throw started and ended in simulated time, its status and, on failure, the
reason (the failing descendant's feedback), in ``context.throws`` and on the blackboard; the
runtime scores each throw over that window from the world's records.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Access, Status

from suture_bt.behaviours import blackboard_keys as keys
from suture_bt.behaviours.skill_behaviour import needs


def failure_reason(node: py_trees.behaviour.Behaviour) -> str:
    """The deepest failed descendant's feedback (where the reason was first said). A failed
    blackboard check (an ``either_or`` option's "Enabled?") only says the option was not
    chosen: it is passed over."""
    for child in node.iterate():
        if isinstance(child, py_trees.behaviours.CheckBlackboardVariableValue):
            continue
        if child is not node and child.status == Status.FAILURE and child.feedback_message:
            if not any(c.status == Status.FAILURE for c in getattr(child, "children", [])):
                return f"{child.name}: {child.feedback_message}"
    return node.feedback_message or "failed"


class ThrowScope(py_trees.decorators.Decorator):
    """Wraps the subtree of throw ``pair``."""

    def __init__(self, pair: int, child: py_trees.behaviour.Behaviour, name: str | None = None):
        super().__init__(name=name or f"Throw {pair}", child=child)
        self.pair = pair
        self.context = None
        self.blackboard = self.attach_blackboard_client(name=self.name)
        self.blackboard.register_key(keys.THROWS.name, access=Access.WRITE)
        self.blackboard.register_key(keys.CURRENT_PAIR.name, access=Access.WRITE)

    def setup(self, **kwargs) -> None:
        self.context = needs(kwargs, "context", f"decorator {self.name!r}")

    def _throws(self) -> dict:
        return self.context.throws

    def initialise(self) -> None:
        self._throws()[self.pair] = {
            "status": "RUNNING",
            "reason": None,
            "t_start": self.context.clock.now(),
            "t_end": None,
        }
        self.blackboard.set(keys.CURRENT_PAIR.name, self.pair, overwrite=True)
        self._publish()

    def update(self) -> Status:
        self.feedback_message = self.decorated.feedback_message
        return self.decorated.status

    def terminate(self, new_status: Status) -> None:
        rec = self._throws().get(self.pair)
        if rec is None or rec["t_end"] is not None:
            return
        rec["t_end"] = self.context.clock.now()
        rec["status"] = new_status.value if new_status != Status.INVALID else "STOPPED"
        if new_status == Status.FAILURE:
            rec["reason"] = failure_reason(self.decorated)
            self.feedback_message = rec["reason"]
        self._publish()

    def _publish(self) -> None:
        self.blackboard.set(
            keys.THROWS.name, {k: dict(v) for k, v in self._throws().items()}, overwrite=True
        )
