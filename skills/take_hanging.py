"""Skills: the inserting arm takes again a needle the tissue holds part way through a pair.

The tissue holds a needle dropped during its insertion: it hangs on the pair's planned circle
with its tip in the ridge (``FindDropped`` found it there: ``driven_in_pair``). The arm comes
in along its jaws onto the wire with the driving hand (the insertion's grasp: jaws across the
needle plane) at the asked arc angle, or the nearest one toward the base that still leaves the
tip room to come out (the planner's grasp limit) and stands clear of the tissue; it closes,
and the measured jaw must show the wire (an empty close backs off before failing). The
estimate that found the needle is anchored to the gripper (the in-hand transform); nothing is
lifted: the insertion that follows drives the needle on along its own circle from where it
hangs (:class:`~suture_bt.skills.insert.Insert` resumes part way).

:class:`LetGoInTissue` makes the same state on purpose: an insertion whose tip came out short
of the rule with its grasp at the planner's limit lets go (the tissue holds the needle) and
backs off, so the arm can take it again further back and drive it on.
"""

from __future__ import annotations

import numpy as np

from suture_bt.planning import NeedleArcError
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import NeedleBelief, NeedleObservation, TaskContext
from suture_bt.skills.dropped import part_way_through, seen_where_it_was
from suture_bt.skills.grasps import END_MARGIN, JAW_CLEARANCE, backed_off, hand, tip_goal
from suture_bt.skills.motion import FINE, feasible, jaw_to, let_go, move_to
from suture_bt.skills.recover import BACK_OFF, JAW_OPEN
from suture_bt.skills.resting_grasp import APPROACH, jaw_heights

#: The held wire point stays this high above the tissue surface (m): the blades close around
#: it (it is already past the entry's jaw clearance at the end of the sweep).
WIRE_CLEARANCE = 0.001


class TakeHanging(Skill):
    """``arm`` takes the needle hanging part way through pair ``pair`` at ``arc_angle``."""

    name = "take hanging needle"

    def __init__(self, context: TaskContext, arm: str, pair: int, arc_angle: float):
        super().__init__(context)
        self.arm_name, self.pair, self.arc_angle = arm, pair, float(arc_angle)

    def program(self) -> Waiting:
        ctx = self.context
        where = f"pair {self.pair}"
        b = ctx.belief
        if b is None or b.holder is not None:
            raise SkillFailure(f"{where}: no estimate of a free needle to take")
        T_needle = b.T_world_needle.copy()
        why = part_way_through(ctx, T_needle, self.pair)
        if why:
            raise SkillFailure(f"{where}: the needle is not hanging part way through: {why}")
        arm = ctx.arm(self.arm_name)
        angle = self._grasp_angle(T_needle, ctx.plan(self.pair, where))
        goal = tip_goal(T_needle, hand(ctx.needle, angle))
        hover = backed_off(goal, APPROACH)
        self.report.update(arc_angle_deg=float(np.rad2deg(angle)), T_world_tip_goal=goal.tolist())
        why = feasible(arm, [hover, goal])
        if why:
            raise SkillFailure(f"{where}: the hanging needle is out of {arm.name}'s reach: {why}")
        self.say(f"{where}: {arm.name} takes the hanging needle at {np.rad2deg(angle):.0f}°")
        arm.arm.jaw.move_jp(np.array([JAW_OPEN]))  # opens on the way
        yield from move_to(ctx.clock, arm, [hover], "come to the hanging needle")
        yield from jaw_to(arm, JAW_OPEN)
        yield from move_to(ctx.clock, arm, [goal], "reach the grasp", FINE, joint_ok=False)
        yield from jaw_to(arm, 0.0)
        held, detail = checks.jaw_holds_wire(arm.jaw_angle())
        if not held:  # leave the needle before failing: open and back off
            yield from jaw_to(arm, JAW_OPEN)
            yield from move_to(ctx.clock, arm, [hover], "back off", FINE, joint_ok=False)
        self.check(f"needle in {arm.name}'s jaw", held, detail)
        seen = NeedleObservation(T_needle, b.stamp, b.angle_std_deg, b.position_std_mm, b.source)
        ctx.believe(seen, arm.name)
        self.say(f"{where}: {arm.name} holds the hanging needle")

    def _grasp_angle(self, T_needle: np.ndarray, arc) -> float:
        """The asked arc angle, or the nearest toward the base whose grasp leaves the tip room
        (the planner's limit) and holds the wire clear of the tissue."""
        needle = self.context.needle
        top = needle.base_angle - END_MARGIN
        reasons = []
        for a in np.linspace(min(self.arc_angle, top), top, 12):
            T_hand = hand(needle, a)
            try:
                arc.check_grasp(T_hand, JAW_CLEARANCE)
            except NeedleArcError as e:
                reasons.append(f"{np.rad2deg(a):.0f}°: {e.reason}")
                continue
            wire, _ = jaw_heights(self.context, T_needle, T_hand)
            if wire >= WIRE_CLEARANCE:
                return float(a)
            reasons.append(f"{np.rad2deg(a):.0f}°: wire {1e3 * wire:.1f} mm above the tissue")
        raise SkillFailure(
            f"pair {self.pair}: no grasp on the hanging needle leaves the tip room and the jaw "
            f"clear of the tissue ({reasons[0]}; ...; {reasons[-1]})"
        )


class LetGoInTissue(Skill):
    """``arm`` lets go of the needle it holds part way through pair ``pair`` (the tissue holds
    it) and backs off along its jaws; the belief becomes that needle, free, where it was."""

    name = "let go in tissue"

    def __init__(self, context: TaskContext, arm: str, pair: int):
        super().__init__(context)
        self.arm_name, self.pair = arm, pair

    def program(self) -> Waiting:
        ctx = self.context
        where = f"pair {self.pair}"
        b = ctx.held_by(self.arm_name, where)
        T_needle = ctx.predicted_needle()
        why = part_way_through(ctx, T_needle, self.pair)
        if why:
            raise SkillFailure(f"{where}: not letting go outside the tissue: {why}")
        arm = ctx.arm(self.arm_name)
        self.say(f"{where}: {arm.name} lets go; the tissue holds the needle")
        yield from let_go(arm, JAW_OPEN)
        ctx.belief = NeedleBelief(
            T_needle, b.stamp, b.source, None, None, b.angle_std_deg, b.position_std_mm
        )
        T_back = backed_off(arm.commanded_tip_world(), BACK_OFF)
        yield from move_to(ctx.clock, arm, [T_back], "back off the held needle")
        # Where the tissue holds it, from the images (the arm's kinematics may have drifted).
        if not (yield from seen_where_it_was(self, T_needle)):
            self.say(f"{where}: not seen where it was let go; the arm's estimate stands")
