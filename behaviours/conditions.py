"""Condition behaviours: questions the tree asks of the evidence (SUCCESS = yes, FAILURE = no).

Each answers from what a real system has: the jaw's measured angle, the belief the skills left
(from images), the calibration state.
"""

from __future__ import annotations

import py_trees
from py_trees.common import Status

from suture_bt.behaviours.skill_behaviour import needs
from suture_bt.skills.checks import (
    JAW_CLOSED_MAX,
    MIN_TIP_OUT,
    jaw_holds_wire,
    last_seen_at_exit,
    seen_out_past_exit,
)
from suture_bt.skills.dropped import driven_in_pair, dropped_by, hanging_in_pair
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


class JawEmpty(_Condition):
    """The arm's jaw holds nothing: open, or closed all the way (no wire between its blades)."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"{arm.upper()} jaw empty?")
        self.arm = arm

    def ask(self) -> tuple[bool, str]:
        held, detail = jaw_holds_wire(self.context.arm(self.arm).jaw_angle())
        return not held, detail


class _FreeNeedleInPair(_Condition):
    """Asks the subclass's ``check(context, pose, pair)`` ('' = yes, else why not) of the free
    needle's estimate; ``yes`` completes the answer's feedback."""

    def __init__(self, pair: int, name: str):
        super().__init__(name)
        self.pair = pair

    def ask(self) -> tuple[bool, str]:
        b = self.context.belief
        if b is None or b.holder is not None:
            return False, "no estimate of a free needle"
        why_not = self.check(self.context, b.T_world_needle, self.pair)
        return not why_not, why_not or f"on pair {self.pair}'s circle, {self.yes}"


class NeedleHangingInPair(_FreeNeedleInPair):
    """The free needle's estimate lies on pair ``pair``'s circle, its tip out past the exit:
    dropped while being pulled through, the extraction can take it again."""

    check, yes = staticmethod(hanging_in_pair), "its tip out"

    def __init__(self, pair: int, name: str | None = None):
        super().__init__(pair, name or f"Needle hanging in pair {pair}?")


class NeedleDrivenInPair(_FreeNeedleInPair):
    """The free needle's estimate lies on pair ``pair``'s circle, its tip past the entry but
    not yet out far enough for the puller: dropped while being inserted, the inserting arm
    can take it again and drive it on."""

    check, yes = staticmethod(driven_in_pair), "part way through"

    def __init__(self, pair: int, name: str | None = None):
        super().__init__(pair, name or f"Needle part way through pair {pair}?")


class TipSeenShort(_Condition):
    """The latest insertion of pair ``pair`` saw its tip cross the exit within the rule but
    short of the tip-out rule (its grasp stopped the drive-on): it may be taken further back
    and driven on, never backed out through the exit."""

    def __init__(self, pair: int, name: str | None = None):
        super().__init__(name or f"Tip out past exit {pair} but short?")
        self.pair = pair

    def ask(self) -> tuple[bool, str]:
        since = self.context.throws.get(self.pair, {}).get("t_start", 0.0)
        seen = last_seen_at_exit(self.context.reports, self.pair, since)
        if not seen_out_past_exit(seen):
            return False, f"no tip seen out past exit {self.pair} in this throw"
        out = seen["tip_out_mm"]
        if out >= 1e3 * MIN_TIP_OUT:
            return False, f"tip seen {out:.1f} mm out: not short"
        return True, f"tip seen {out:.1f} mm out past exit {self.pair} (< {1e3 * MIN_TIP_OUT:g})"


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


def _closed_empty(angle: float) -> bool:
    """A jaw closed (≤ the closing threshold) below the wire: nothing between its blades."""
    return angle <= JAW_CLOSED_MAX and not jaw_holds_wire(angle)[0]


class GraspMissed(_Condition):
    """``arm`` closed on nothing while the needle is still believed in another arm's jaw."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"{arm.upper()} closed empty?")
        self.arm = arm

    def ask(self) -> tuple[bool, str]:
        b = self.context.belief
        angle = self.context.arm(self.arm).jaw_angle()
        if b is not None and b.holder == self.arm:
            return False, f"{self.arm} is believed to hold the needle: not a missed grasp"
        if not _closed_empty(angle):
            return False, f"{self.arm}'s jaw is not closed empty ({jaw_holds_wire(angle)[1]})"
        return True, f"{self.arm} missed: {jaw_holds_wire(angle)[1]}"


class NeedleStillHeld(py_trees.behaviour.Behaviour):
    """A watch (RUNNING while all is well): FAILURE once the believed holder's jaw has
    closed below the wire, i.e. the needle dropped out of it."""

    def __init__(self, name: str = "Needle still held?"):
        super().__init__(name)
        self.context = None

    def setup(self, **kwargs) -> None:
        self.context = needs(kwargs, "context", f"watch {self.name!r}")

    def update(self) -> Status:
        holder = self.context.holder()
        if holder is None:
            self.feedback_message = "no holder to watch"
            return Status.RUNNING
        angle = self.context.arm(holder).jaw_angle()
        if _closed_empty(angle):
            self.feedback_message = f"needle dropped by {holder} ({jaw_holds_wire(angle)[1]})"
            return Status.FAILURE
        self.feedback_message = f"{holder}'s jaw at {angle:.3f} rad"
        return Status.RUNNING


class NeedleDropped(_Condition):
    """The guard of the dropped-needle recovery: the believed holder's jaw closed below the
    wire (a throw that failed for another reason is not recovered by a pick-up)."""

    def __init__(self, name: str = "Needle dropped?"):
        super().__init__(name)

    def ask(self) -> tuple[bool, str]:
        arm, why = dropped_by(self.context)
        return arm is not None, why


class CalibrationLost(_Condition):
    """The guard of the recalibration: ``arm`` was calibrated, and a check has since found
    its calibration no longer holds (marked lost)."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"{arm.upper()}'s calibration lost?")
        self.arm = arm

    def ask(self) -> tuple[bool, str]:
        a = self.context.arm(self.arm)
        lost = a.offset_estimate is not None and not a.calibrated
        return lost, f"{self.arm}'s calibration " + ("lost" if lost else "holds")
