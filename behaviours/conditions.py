"""Condition behaviours: questions the tree asks of the evidence (SUCCESS = yes, FAILURE = no).

Each answers from what a real system has: the jaw's measured angle, the belief the skills left
(from images), the calibration state.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from suture_bt.behaviours.skill_behaviour import needs
from suture_bt.skills.checks import jaw_holds_wire
from suture_bt.skills.reach import pair_reach


class _Condition(py_trees.behaviour.Behaviour):
    def __init__(self, name: str):
        super().__init__(name)
        self.context = None

    def setup(self, **kwargs) -> None:
        self.context = needs(kwargs, "context", f"condition {self.name!r}")

    def update(self) -> Status:
        ok, why = self.ask()
        self.feedback_message = why
        return Status.SUCCESS if ok else Status.FAILURE

    def ask(self) -> tuple[bool, str]:
        raise NotImplementedError


class JawHoldsSomething(_Condition):
    """The arm's jaw is closed but stopped short of empty-closed: a wire is between its blades."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"{arm.upper()} jaw holds the needle?")
        self.arm = arm

    def ask(self) -> tuple[bool, str]:
        angle = self.context.arm(self.arm).jaw_angle()
        closed = angle < 0.2
        ok, detail = jaw_holds_wire(angle)
        return closed and ok, detail if closed else f"jaw open at {angle:.2f} rad"


class NeedleLocalised(_Condition):
    """The tree has a needle estimate (held: with the holder's in-hand transform)."""

    def __init__(self, holder: str | None = None, name: str | None = None):
        super().__init__(name or "Needle localised?")
        self.holder = holder

    def ask(self) -> tuple[bool, str]:
        b = self.context.belief
        if b is None:
            return False, "no needle estimate yet"
        if self.holder is not None and (b.holder != self.holder or b.T_tip_needle is None):
            return False, f"needle not known to be in {self.holder}'s jaw (holder {b.holder})"
        return True, f"needle estimate from {b.source}, holder {b.holder}"


class ArmCalibrated(_Condition):
    """The arm's joint offset has been calibrated."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"{arm.upper()} calibrated?")
        self.arm = arm

    def ask(self) -> tuple[bool, str]:
        ok = self.context.arm(self.arm).calibrated
        return ok, "calibrated" if ok else "not calibrated"


class PairsInReach(_Condition):
    """Both arms can reach every planned pose of the throws through ``pairs`` (IK, no motion)."""

    def __init__(self, pairs: tuple[int, ...], inserter: str, puller: str, name: str | None = None):
        super().__init__(name or "Pairs in reach?")
        self.pairs, self.inserter, self.puller = tuple(pairs), inserter, puller

    def ask(self) -> tuple[bool, str]:
        for pair in self.pairs:
            why = pair_reach(self.context, pair, self.inserter, self.puller)
            if why:
                return False, why
        return True, f"pairs {', '.join(map(str, self.pairs))} in reach of both arms"

