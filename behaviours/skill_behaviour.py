"""One py_trees behaviour per skill: ``setup`` receives the context, ``initialise`` starts the
skill, ``update`` steps it by one tick, ``terminate`` stops it when pre-empted.

The skill's one-line feedback becomes ``feedback_message`` (a FAILURE carries its reason), its
report is appended to ``context.reports`` when it ends, and the belief it leaves is published
on the blackboard (:mod:`blackboard_keys`).
"""

from __future__ import annotations

import py_trees
from py_trees.common import Access, Status

from suture_bt.behaviours import blackboard_keys as keys
from suture_bt.skills.base import Skill, SkillStatus

_STATUS = {
    SkillStatus.RUNNING: Status.RUNNING,
    SkillStatus.SUCCESS: Status.SUCCESS,
    SkillStatus.FAILURE: Status.FAILURE,
}


def needs(kwargs: dict, name: str, who: str):
    """A setup argument, or a clear error naming the behaviour that needed it."""
    if name not in kwargs:
        raise RuntimeError(f"{who} needs setup({name}=...) (build trees with the runtime)")
    return kwargs[name]


class SkillBehaviour(py_trees.behaviour.Behaviour):
    """Base class: subclasses implement :meth:`make_skill`."""

    def __init__(self, name: str):
        super().__init__(name)
        self.context = None
        self.tick_dt = 0.0
        self.skill: Skill | None = None
        self.blackboard = self.attach_blackboard_client(name=name)
        for key in keys.ALL_KEYS:
            self.blackboard.register_key(key.name, access=Access.WRITE)

    def setup(self, **kwargs) -> None:
        self.context = needs(kwargs, "context", f"behaviour {self.name!r}")
        self.tick_dt = float(needs(kwargs, "tick_dt", f"behaviour {self.name!r}"))

    def make_skill(self) -> Skill:
        raise NotImplementedError

    def initialise(self) -> None:
        if self.context is None:
            raise RuntimeError(f"behaviour {self.name!r} was not set up (call tree.setup(...))")
        self.skill = self.make_skill()
        self.skill.start()
        self.feedback_message = self.skill.feedback

    def update(self) -> Status:
        status = self.skill.step(self.tick_dt)
        self.feedback_message = self.skill.feedback
        if status is not SkillStatus.RUNNING:
            self.context.reports.append(self.skill.report | {"behaviour": self.name})
            publish(self.blackboard, self.context)
        return _STATUS[status]

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.skill is not None:
            if self.skill.status is SkillStatus.RUNNING:
                self.skill.stop()
                self.feedback_message = "pre-empted"


def publish(blackboard, context) -> None:
    """Write the context's belief and calibration state to the blackboard."""
    b = context.belief
    if b is not None:
        blackboard.set(keys.NEEDLE_POSE.name, b.T_world_needle.tolist(), overwrite=True)
        blackboard.set(keys.NEEDLE_HOLDER.name, b.holder, overwrite=True)
        blackboard.set(keys.NEEDLE_SOURCE.name, b.source, overwrite=True)
        blackboard.set(keys.NEEDLE_SPREAD_DEG.name, float(b.angle_std_deg), overwrite=True)
    for name, arm in context.arms.items():
        blackboard.set(keys.calibrated(name).name, bool(arm.calibrated), overwrite=True)
        if arm.offset_estimate is not None:
            blackboard.set(
                keys.offset_estimate(name).name,
                [float(v) for v in arm.offset_estimate],
                overwrite=True,
            )
