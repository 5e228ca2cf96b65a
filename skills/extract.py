"""Skill: the other arm takes the emerged part of the needle and pulls it through.

The puller comes in along its jaws onto the needle just behind the emerged tip, closes (the
jaw's measured angle must show the wire), the inserting arm opens and backs off, the puller
continues the planned circle until the needle's base has left the exit, lifts it along the exit
normal, and a fresh image must show the needle clear of the tissue and where the puller's
gripper put it.

A needle the puller dropped while pulling hangs in the tissue on the pair's circle with no
holder (``FindDropped`` found it there): the same skill takes it again where it hangs (no
inserter to let go) and pulls it through from its sweep angle; the report says ``resumed``.
"""

from __future__ import annotations

import numpy as np

from suture_bt.planning import gripper_poses
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import NeedleNotSeen, TaskContext
from suture_bt.skills.grasps import backed_off, pulling_hand, tip_goal
from suture_bt.skills.insert import SWEEP
from suture_bt.skills.localize_needle import LocalizeNeedle
from suture_bt.skills.motion import FINE, follow_poses, jaw_to, let_go, move_to

#: Approach along the jaws, the inserter's back-off and the lift after extraction (m).
APPROACH, BACK_OFF, LIFT = 0.008, 0.010, 0.012
JAW_OPEN = 0.8


class Extract(Skill):
    """``puller`` pulls the needle, inserted by ``inserter``, through pair ``pair``."""

    name = "extract"

    def __init__(self, context: TaskContext, puller: str, inserter: str, pair: int):
        super().__init__(context)
        self.puller, self.inserter, self.pair = puller, inserter, pair

    def program(self) -> Waiting:
        ctx = self.context
        puller, inserter = ctx.arm(self.puller), ctx.arm(self.inserter)
        where = f"pair {self.pair}"
        resumed = ctx.belief is not None and ctx.belief.holder is None
        if not resumed:
            ctx.held_by(self.inserter, where)
        self.report["resumed"] = resumed
        _, exit_ = ctx.phantom.pair(self.pair)
        arc = ctx.plan(self.pair, where)
        T_needle = ctx.predicted_needle()
        goal = tip_goal(T_needle, pulling_hand(ctx.needle))
        what = "the needle hanging in the tissue" if resumed else "the emerged tip"
        self.say(f"{where}: {self.puller} takes {what}")
        puller.arm.jaw.move_jp(np.array([JAW_OPEN]))  # opens on the way
        try:
            yield from move_to(ctx.clock, puller, [backed_off(goal, APPROACH)], "approach the tip")
        except SkillFailure as e:
            raise SkillFailure(f"{where}: exit out of {self.puller}'s reach: {e.reason}") from None
        yield from jaw_to(puller, JAW_OPEN)
        yield from move_to(ctx.clock, puller, [goal], "reach the tip", FINE, joint_ok=False)
        yield from jaw_to(puller, 0.0)
        self.check(f"needle in {self.puller}'s jaw", *checks.jaw_holds_wire(puller.jaw_angle()))
        if not resumed:
            self.say(f"{where}: {self.inserter} lets go")
            yield from let_go(inserter, JAW_OPEN)
            yield from move_to(
                ctx.clock,
                inserter,
                [backed_off(inserter.commanded_tip_world(), BACK_OFF)],
                "back off",
            )
        ctx.belief.holder = self.puller
        ctx.belief.T_tip_needle = np.linalg.inv(puller.tip_world()) @ T_needle
        T_gn = ctx.belief.T_tip_needle.copy()
        self.say(f"{where}: pulling the needle through {exit_.name}")
        # Continue the circle from where the needle is now (its sweep angle: the insertion
        # may have driven on past the planned end).
        phi, _ = arc.sweep_angle_of(T_needle[:3, :3])
        sweep = gripper_poses(arc.extraction(start_angle=phi, **SWEEP), T_gn)
        yield from follow_poses(ctx.clock, puller, sweep, f"{where}: pull the needle through")
        T_up = puller.commanded_tip_world()
        T_up[:3, 3] += LIFT * exit_.normal
        yield from move_to(ctx.clock, puller, [T_up], "lift the needle")
        yield from self._confirm(puller, T_gn)

    def _confirm(self, puller, T_gn) -> Waiting:
        """A fresh estimate must agree with the puller's gripper and lie clear of the tissue;
        when the look from the lift pose fails, the puller presents the needle and looks again
        (a needle still caught in the tissue would not be where the gripper put it)."""
        ctx = self.context
        predicted = puller.tip_world() @ T_gn
        try:
            obs = ctx.sensor.observe(predicted, prior_checked=True)
            ok, detail = checks.poses_agree(obs.T_world_needle, predicted)
            if not ok:
                raise NeedleNotSeen(f"answer disagrees with the arm: {detail}")
            ctx.believe(obs, self.puller)
            ok, detail = checks.clear_of_tissue(
                obs.T_world_needle, ctx.needle, ctx.phantom.T_world_phantom, ctx.phantom.ports()
            )
            self.check(f"pair {self.pair}: needle clear of the tissue", ok, detail)
        except NeedleNotSeen as e:
            self.report["refusals"] = [e.reason]
            yield from self.run(LocalizeNeedle(ctx, self.puller))
            ok, detail = checks.poses_agree(ctx.belief.T_world_needle, puller.tip_world() @ T_gn)
            if not ok:
                ok, detail = yield from self._second_look(puller, T_gn, detail)
            self.check(f"needle moved with {self.puller} out of the tissue", ok, detail)
            detail = f"needle presented: {detail}"
        self.say(f"pair {self.pair}: needle pulled through ({detail})")

    def _second_look(self, puller, T_gn, first_detail: str) -> Waiting:
        """One presented answer off the gripper may be a confident wrong twin (a campaign
        trial: 47° off, its wire between the blades): another presentation decides. Agreeing
        with the gripper, the needle moved with it; agreeing with the first answer instead,
        the needle turned in the puller's jaw (it is held, clear of the tissue, and the new
        estimate is kept for the hand-back); neither, or no answer: (False, both details)."""
        ctx = self.context
        first = ctx.belief
        try:
            look = LocalizeNeedle(ctx, self.puller, avoid=(puller.commanded_tip_world(),))
            yield from self.run(look)
        except SkillFailure as e:
            ctx.belief = first
            return False, f"{first_detail}; no second view: {e.reason}"
        second = ctx.belief.T_world_needle
        like_grip, detail = checks.poses_agree(second, puller.tip_world() @ T_gn)
        like_first, _ = checks.poses_agree(second, puller.tip_world() @ first.T_tip_needle)
        self.report["second_look"] = dict(
            agrees_with_gripper=like_grip, agrees_with_first=like_first
        )
        if like_grip:
            return True, f"{detail} (a second view refutes the first: {first_detail})"
        if like_first:
            ok, clear = checks.clear_of_tissue(
                second, ctx.needle, ctx.phantom.T_world_phantom, ctx.phantom.ports()
            )
            return ok, f"turned in {self.puller}'s jaw, seen twice alike ({first_detail}); {clear}"
        return False, f"{first_detail}; a second view agrees with neither ({detail})"
