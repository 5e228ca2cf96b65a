"""``NeedleStart``: decide from the inserting arm's jaw whether the needle starts in it.

A closed jaw stopped on the wire (its measured angle) means the needle is in the jaw (SRC Task
3); otherwise it is assumed to rest on the tissue, to be localised and picked up. Writes
``/task/needle_start`` ("jaw" or "tissue") for the tree's either-or.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Access, Status

from suture_bt.behaviours import blackboard_keys as keys
from suture_bt.behaviours.skill_behaviour import needs
from suture_bt.skills.checks import jaw_holds_wire


class NeedleStart(py_trees.behaviour.Behaviour):
    """Always SUCCESS once it has written its answer (the answer is the point)."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"Needle in {arm.upper()}'s jaw or on the tissue?")
        self.arm = arm
        self.context = None
        self.blackboard = self.attach_blackboard_client(name=self.name)
        self.blackboard.register_key(keys.NEEDLE_START.name, access=Access.WRITE)

    def setup(self, **kwargs) -> None:
        self.context = needs(kwargs, "context", f"behaviour {self.name!r}")

    def update(self) -> Status:
        angle = self.context.arm(self.arm).jaw_angle()
        held, detail = jaw_holds_wire(angle)
        held = held and angle < 0.2
        start = "jaw" if held else "tissue"
        self.context.start_holder = self.arm if held else None
        self.blackboard.set(keys.NEEDLE_START.name, start, overwrite=True)
        self.feedback_message = f"needle starts in the {start} ({detail})"
        return Status.SUCCESS
