"""Skill: the pulling arm waits near the exit, jaw open, while the other arm inserts.

From the planned circle of the pair it knows where the tip will stand at the end of the
insertion, so it can come most of the way in advance: to the pulling grasp on that planned
needle, backed off along its jaws by ``STANDBY_DISTANCE`` and out of the cameras' sight of
the emerging tip. The extraction then starts from
there with a short approach onto the needle as actually seen. Nothing is confirmed here but
reach: the extraction checks its own grasp.
"""

from __future__ import annotations

import numpy as np

from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import TaskContext
from suture_bt.skills.grasps import backed_off, pulling_hand, tip_goal
from suture_bt.skills.line_of_sight import clear_tip_pose
from suture_bt.skills.motion import feasible, move_to

#: How far back along its jaws from the planned pulling grasp the arm waits (m).
STANDBY_DISTANCE = 0.015
#: Jaw opening while waiting (rad): the extraction's opening.
JAW_OPEN = 0.8


class StandBy(Skill):
    """``arm`` waits near the exit of pair ``pair`` (1-based), ready to take the tip."""

    name = "stand by"

    def __init__(self, context: TaskContext, arm: str, pair: int):
        super().__init__(context)
        self.arm_name, self.pair = arm, pair
        self.arms = (arm,)

    def standby_pose(self) -> np.ndarray:
        """World tip pose to wait at; SkillFailure when the pair cannot be planned."""
        ctx = self.context
        arc = ctx.plan(self.pair, f"pair {self.pair}")
        T_end = arc.needle_pose(arc.insert_end_angle)
        T = backed_off(tip_goal(T_end, pulling_hand(ctx.needle)), STANDBY_DISTANCE)
        # Out of the cameras' sight of the emerging tip: the insertion confirms from images.
        rcm = ctx.arm(self.arm_name).base_frame()[:3, 3]
        cleared = clear_tip_pose(ctx, T, rcm, arc.tip_position(arc.insert_end_angle))
        return T if cleared is None else cleared

    def program(self) -> Waiting:
        ctx = self.context
        arm = ctx.arm(self.arm_name)
        T = self.standby_pose()
        self.report["standby_pose"] = T.tolist()
        reason = feasible(arm, [T])
        if reason:
            raise SkillFailure(
                f"pair {self.pair}: {self.arm_name} cannot wait at the exit: {reason}"
            )
        self.say(f"pair {self.pair}: {self.arm_name} waits at the exit")
        arm.arm.jaw.move_jp(np.array([JAW_OPEN]))
        yield from move_to(ctx.clock, arm, [T], "stand by at the exit")
