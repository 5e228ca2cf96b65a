"""Skill: before an insertion, look at the held needle over the entry: has it slipped?

A slip turns the needle in the jaw or slides it along its wire; the joints cannot tell, only
the images can. The inserting arm brings the needle to where the insertion's approach starts
(lifted above the entry, the pose the insertion goes to first), the needle is localised there
(presented to the cameras only when that view is refused) and the estimate is compared with
the pose the belief's in-hand transform predicts. Agreeing (``checks.poses_agree``), the
in-hand estimate stands unchanged; disagreeing, the needle slipped: the fresh estimate becomes
the in-hand transform and the report says ``slipped`` (the tree then checks the planner's
grasp limit on it and re-grasps when it leaves the tip too little room). A needle that no view
localises keeps its estimate, and the report says it was not re-checked.
"""

from __future__ import annotations

import numpy as np

from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import TaskContext
from suture_bt.skills.grasps import held_arc_angle
from suture_bt.skills.insert import LIFT, PRE_ARC
from suture_bt.skills.line_of_sight import clear_tip_pose
from suture_bt.skills.localize_needle import LocalizeNeedle
from suture_bt.skills.motion import feasible, move_to, together
from suture_bt.transforms import invert


class CheckInHand(Skill):
    """``arm`` brings its needle over pair ``pair``'s entry; a slip there is re-estimated."""

    name = "check in-hand pose"

    def __init__(self, context: TaskContext, arm: str, pair: int):
        super().__init__(context)
        self.arm_name, self.pair = arm, pair

    def program(self) -> Waiting:
        ctx = self.context
        arm = ctx.arm(self.arm_name)
        where = f"pair {self.pair}"
        kept = ctx.held_by(self.arm_name, where)
        entry, _ = ctx.phantom.pair(self.pair)
        arc = ctx.plan(self.pair, where)
        T_gn = kept.T_tip_needle.copy()
        lift = arc.approach_poses(PRE_ARC, LIFT)[0] @ invert(T_gn)
        self.say(f"{where}: bringing the needle over {entry.name} to look at it")
        try:
            approach = move_to(ctx.clock, arm, [lift], "approach the entry")
            yield from together(approach, *self._make_way((lift @ T_gn)[:3, 3]))
        except SkillFailure as e:
            raise SkillFailure(
                f"{where}: entry out of {self.arm_name}'s reach: {e.reason}"
            ) from None
        seen = yield from self._look()
        predicted = arm.tip_world() @ T_gn  # where the arm stands when it looked
        if seen is None:
            ctx.belief = kept
            self.report["checked"] = False
            self.say(f"{where}: in-hand pose not re-checked (no view localised the needle)")
            return
        ok, detail = checks.poses_agree(seen.T_world_needle, predicted)
        self.report.update(checked=True, slipped=not ok, detail=detail)
        if ok:
            ctx.belief = kept  # the estimate the grasp was confirmed with stands
            self.say(f"{where}: in-hand pose confirmed ({detail})")
            return
        was = np.rad2deg(held_arc_angle(ctx.needle, T_gn))
        now = np.rad2deg(held_arc_angle(ctx.needle, seen.T_tip_needle))
        self.report["held_arc_deg"] = (float(was), float(now))
        self.say(
            f"{where}: needle slipped in {self.arm_name}'s jaw ({detail}); in-hand pose "
            f"re-estimated: held at {now:.0f}°, was {was:.0f}°"
        )

    def _make_way(self, target: np.ndarray) -> list[Waiting]:
        """Moves that take the other arms out of the cameras' sight of ``target``."""
        ctx = self.context
        moves = []
        for name, other in ctx.arms.items():
            if name == self.arm_name:
                continue
            T = clear_tip_pose(ctx, other.commanded_tip_world(), other.base_frame()[:3, 3], target)
            if T is not None and not feasible(other, [T]):
                moves.append(move_to(ctx.clock, other, [T], "make way for the cameras"))
        return moves

    def _look(self) -> Waiting:
        """The fresh belief from this view, else from a presentation; None when refused."""
        ctx = self.context
        for present in (False, True):
            try:
                yield from self.run(LocalizeNeedle(ctx, self.arm_name, present=present))
                return ctx.belief
            except SkillFailure as e:
                self.report.setdefault("refusals", []).append(e.reason)
        return None
