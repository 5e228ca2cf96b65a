"""The action behaviours of the suture trees, one per skill (each a few lines over
:class:`SkillBehaviour`): what the node is called, which skill it starts, with what arguments.
"""

from __future__ import annotations

from collections.abc import Callable

from suture_bt.behaviours.skill_behaviour import SkillBehaviour
from suture_bt.planning import NeedleArcError, plan_needle_arc
from suture_bt.skills.calibrate_arm import CalibrateArm
from suture_bt.skills.checks import last_seen_at_exit
from suture_bt.skills.context import TaskContext
from suture_bt.skills.dropped import FindDropped
from suture_bt.skills.extract import Extract
from suture_bt.skills.grasps import (
    END_MARGIN,
    free_angle,
    held_arc_angle,
    insertion_grasp_angle,
)
from suture_bt.skills.handover import Handover
from suture_bt.skills.in_hand_check import CheckInHand
from suture_bt.skills.insert import Insert
from suture_bt.skills.lay_down import LayDown
from suture_bt.skills.localize_needle import LocalizeNeedle
from suture_bt.skills.pick_up import PickUp
from suture_bt.skills.recover import BackOut, OpenAndBackOff
from suture_bt.skills.stand_by import StandBy
from suture_bt.skills.take_hanging import LetGoInTissue, TakeHanging

#: Chooses the taker's arc angle when a handover starts (the belief is known only then).
AngleRule = Callable[[TaskContext], float]


class Calibrate(SkillBehaviour):
    """Calibrate one arm's joint offset (empty jaw)."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"Calibrate {arm.upper()}")
        self.arm = arm

    def make_skill(self):
        return CalibrateArm(self.context, self.arm)


class Localize(SkillBehaviour):
    """Localise the needle (``holder``: the arm holding it, presented to the cameras)."""

    def __init__(self, holder: str | None, name: str | None = None):
        super().__init__(
            name or (f"Localize needle in {holder.upper()}" if holder else "Localize needle")
        )
        self.holder = holder

    def make_skill(self):
        return LocalizeNeedle(self.context, self.holder)


class HandOver(SkillBehaviour):
    """Hand the needle from ``giver`` to ``taker`` at the arc angle ``angle(context)``."""

    def __init__(
        self,
        giver: str,
        taker: str,
        angle: AngleRule,
        pulling: bool = False,
        next_pair: int | None = None,
        name: str | None = None,
    ):
        super().__init__(name or f"Hand over {giver.upper()} → {taker.upper()}")
        self.giver, self.taker, self.angle, self.pulling = giver, taker, angle, pulling
        self.next_pair = next_pair

    def make_skill(self):
        return Handover(
            self.context,
            self.giver,
            self.taker,
            self.angle(self.context),
            self.pulling,
            next_pair=self.next_pair,
        )


class InsertNeedle(SkillBehaviour):
    """Drive the needle through a port pair (``confirm_only``: look again at the tip)."""

    def __init__(self, arm: str, pair: int, name: str | None = None, confirm_only: bool = False):
        super().__init__(name or f"Insert pair {pair}")
        self.arm, self.pair, self.confirm_only = arm, pair, confirm_only

    def make_skill(self):
        return Insert(self.context, self.arm, self.pair, self.confirm_only)


class ExtractNeedle(SkillBehaviour):
    """The other arm pulls the needle through a port pair."""

    def __init__(self, puller: str, inserter: str, pair: int, name: str | None = None):
        super().__init__(name or f"Extract pair {pair}")
        self.puller, self.inserter, self.pair = puller, inserter, pair

    def make_skill(self):
        return Extract(self.context, self.puller, self.inserter, self.pair)


class StandByAtExit(SkillBehaviour):
    """The pulling arm waits near a pair's exit while the other arm inserts."""

    def __init__(self, arm: str, pair: int, name: str | None = None):
        super().__init__(name or f"{arm.upper()} stands by at exit {pair}")
        self.arm, self.pair = arm, pair

    def make_skill(self):
        return StandBy(self.context, self.arm, self.pair)


class PickUpNeedle(SkillBehaviour):
    """Localise the needle resting on the tissue and pick it up at ``angle(context)``
    (``free``: another arc angle will do when that one is out of reach)."""

    def __init__(self, arm: str, angle: AngleRule, name: str | None = None, free: bool = False):
        super().__init__(name or f"Pick up the needle with {arm.upper()}")
        self.arm, self.angle, self.free = arm, angle, free

    def make_skill(self):
        return PickUp(self.context, self.arm, self.angle(self.context), self.free)


class CheckNeedleInHand(SkillBehaviour):
    """Before inserting: the needle seen over the entry where its in-hand pose says (else it
    slipped, and the in-hand pose is re-estimated)."""

    def __init__(self, arm: str, pair: int, name: str | None = None):
        super().__init__(name or f"Needle still as held? (pair {pair})")
        self.arm, self.pair = arm, pair

    def make_skill(self):
        return CheckInHand(self.context, self.arm, self.pair)


class FindDroppedNeedle(SkillBehaviour):
    """Recovery after a drop: let go, localise the fallen needle, check ``picker`` can take it
    at ``angle(context)`` (else fail saying why: in the tissue, on its edge, out of reach)."""

    def __init__(
        self, picker: str, angle: AngleRule, pair: int | None = None, name: str | None = None
    ):
        super().__init__(name or "Find the dropped needle")
        self.picker, self.angle, self.pair = picker, angle, pair

    def make_skill(self):
        return FindDropped(self.context, self.picker, self.angle(self.context), self.pair)


class TakeHangingNeedle(SkillBehaviour):
    """Recovery after a drop part way through a pair: ``arm`` takes the needle again where
    the tissue holds it, at ``angle(context)`` (the insertion then drives it on)."""

    def __init__(self, arm: str, pair: int, angle: AngleRule, name: str | None = None):
        super().__init__(name or f"{arm.upper()} takes the needle hanging in pair {pair}")
        self.arm, self.pair, self.angle = arm, pair, angle

    def make_skill(self):
        return TakeHanging(self.context, self.arm, self.pair, self.angle(self.context))


class LetGoOfNeedleInTissue(SkillBehaviour):
    """``arm`` lets go of the needle it holds part way through pair ``pair`` and backs off
    (the tissue holds it), to take it again elsewhere."""

    def __init__(self, arm: str, pair: int, name: str | None = None):
        super().__init__(name or f"{arm.upper()} lets go in pair {pair}")
        self.arm, self.pair = arm, pair

    def make_skill(self):
        return LetGoInTissue(self.context, self.arm, self.pair)


class LayDownNeedle(SkillBehaviour):
    """Empty ``arm``'s jaw for its calibration: lay the needle on the tissue where ``arm`` can
    pick it up again at ``angle(context)``, and let go."""

    def __init__(self, arm: str, angle: AngleRule, name: str | None = None):
        super().__init__(name or f"{arm.upper()} lays the needle on the tissue")
        self.arm, self.angle = arm, angle

    def make_skill(self):
        return LayDown(self.context, self.arm, self.angle(self.context))


# ------------------------------------------------------------------ angle rules
def grasp_for_pairs(pairs: tuple[int, ...]) -> AngleRule:
    """The inserting grasp that leaves room for the tip to come out on all of ``pairs``."""

    def rule(ctx: TaskContext) -> float:
        angles = []
        for p in pairs:
            try:
                angles.append(
                    insertion_grasp_angle(plan_needle_arc(*ctx.phantom.pair(p), ctx.needle))
                )
            except NeedleArcError:
                continue  # the insert skill reports this pair's planning failure itself
        return max(angles) if angles else ctx.needle.base_angle - 0.2

    return rule


def furthest_back(ctx: TaskContext) -> float:
    """The grasp nearest the needle's base that keeps the end margin: the most room for the
    tip to be driven on."""
    return float(ctx.needle.base_angle - END_MARGIN)


def away_from_holder_and(later: AngleRule) -> AngleRule:
    """An angle far from the current holder's grasp and from a grasp needed later."""

    def rule(ctx: TaskContext) -> float:
        avoid = [later(ctx)]
        b = ctx.belief
        if b is not None and b.T_tip_needle is not None:
            avoid.append(held_arc_angle(ctx.needle, b.T_tip_needle))
        return free_angle(ctx.needle, avoid)

    return rule


class OpenAndBackOffArm(SkillBehaviour):
    """Recovery after an empty close: ``arm`` opens its jaw and backs off along its jaws."""

    def __init__(self, arm: str, name: str | None = None):
        super().__init__(name or f"{arm.upper()} opens and backs off")
        self.arm = arm

    def make_skill(self):
        return OpenAndBackOff(self.context, self.arm)


class BackOutNeedle(SkillBehaviour):
    """Recovery after an unconfirmed insertion: back the needle out along its arc."""

    def __init__(self, arm: str, pair: int, name: str | None = None):
        super().__init__(name or f"Back out of pair {pair}")
        self.arm, self.pair = arm, pair

    def make_skill(self):
        swept = None  # the grasp the last insertion of this pair swept with
        for r in reversed(self.context.reports):
            if r.get("skill") == "insert" and "T_tip_needle" in r:
                swept = r["T_tip_needle"]
                break
        since = self.context.throws.get(self.pair, {}).get("t_start", 0.0)
        seen = last_seen_at_exit(self.context.reports, self.pair, since)
        return BackOut(self.context, self.arm, self.pair, swept, seen)
