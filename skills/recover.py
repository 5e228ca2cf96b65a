"""Recovery skills the trees run between two attempts of a failed step.

- :class:`OpenAndBackOff`: a grasp closed empty; the arm opens its jaw and backs off along its
  jaws (or, where that pose is out of reach, draws back along its shaft), so the next attempt
  comes in afresh.
- :class:`BackOut`: an insertion was not confirmed; the inserting arm drives the needle back
  along the circle it came in on (the planned sweep reversed, from where the needle is now to
  the pre-insertion pose), then lifts it along the entry normal. The needle is rigid in the
  jaw, so reversing the gripper's own motion retraces the needle's path through the tissue
  whatever the in-hand error was. A tip seen out past the exit is never backed out: it would
  re-enter the tissue there (a campaign trial's was, and scored a stab).
"""

from __future__ import annotations

import numpy as np

from suture_bt.planning import gripper_poses
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import TaskContext
from suture_bt.skills.grasps import backed_off
from suture_bt.skills.insert import LIFT, PRE_ARC, SWEEP
from suture_bt.skills.motion import feasible, follow_poses, jaw_to, move_to, retract

#: Jaw opening and back-off distance along the jaws after an empty close (rad, m).
JAW_OPEN, BACK_OFF = 0.8, 0.010
#: The commanded needle must be this close to the planned circle to be backed out along it.
ON_ARC_M, ON_ARC_DEG = 0.002, 5.0


class OpenAndBackOff(Skill):
    """``arm`` opens its jaw and backs off ``distance`` along its jaws."""

    name = "open and back off"

    def __init__(self, context: TaskContext, arm: str, distance: float = BACK_OFF):
        super().__init__(context)
        self.arm_name, self.distance = arm, float(distance)
        self.arms = (arm,)

    def program(self) -> Waiting:
        arm = self.context.arm(self.arm_name)
        self.say(f"{self.arm_name} opens its jaw")
        yield from jaw_to(arm, JAW_OPEN)
        T_back = backed_off(arm.commanded_tip_world(), self.distance)
        why = feasible(arm, [T_back])
        if why:  # e.g. the wrist at its limit (a campaign trial's taker ended the run here)
            self.report["retracted_instead"] = why
            yield from retract(self.context.clock, arm, self.distance, "draw back")
            self.say(f"{self.arm_name} opened and drew back {1e3 * self.distance:.0f} mm")
            return
        yield from move_to(self.context.clock, arm, [T_back], "back off")
        self.say(f"{self.arm_name} opened and backed off {1e3 * self.distance:.0f} mm")


class BackOut(Skill):
    """``arm`` (holding the needle) backs it out of pair ``pair`` along the arc;
    ``T_tip_needle`` is the grasp the insertion swept with (default: the belief's)."""

    name = "back out"

    def __init__(
        self,
        context: TaskContext,
        arm: str,
        pair: int,
        T_tip_needle: np.ndarray | None = None,
        seen: dict | None = None,
    ):
        super().__init__(context)
        self.arm_name, self.pair = arm, pair
        self.T_tip_needle = None if T_tip_needle is None else np.asarray(T_tip_needle, float)
        self.seen = seen
        self.arms = (arm,)

    def program(self) -> Waiting:
        ctx = self.context
        where = f"pair {self.pair}"
        if checks.seen_out_past_exit(self.seen):
            raise SkillFailure(
                f"{where}: the tip was seen out past exit {self.pair} "
                f"({self.seen['tip_out_mm']:.1f} mm, crossing {self.seen['lateral_mm']:.1f} mm "
                "from it): backing out would re-enter the tissue there"
            )
        b = ctx.held_by(self.arm_name, where)
        arm = ctx.arm(self.arm_name)
        entry, _ = ctx.phantom.pair(self.pair)
        arc = ctx.plan(self.pair, where)
        T_gn = b.T_tip_needle if self.T_tip_needle is None else self.T_tip_needle
        T_now = arm.commanded_tip_world() @ T_gn
        phi, turn = self._sweep_angle(arc, T_now)
        off = float(np.linalg.norm(T_now[:3, 3] - arc.T_world_needle_entry[:3, 3]))
        if off > ON_ARC_M or turn > ON_ARC_DEG:
            raise SkillFailure(
                f"{where}: the needle is not on the planned arc ({1e3 * off:.1f} mm, "
                f"{turn:.1f}° from it): nothing to back out"
            )
        start = arc.pre_insertion_angle(PRE_ARC)
        self.report["from_angle_deg"] = float(np.rad2deg(phi))
        self.say(f"{where}: backing the needle out of {entry.name} along the arc")
        if phi > start + 1e-3:
            back = gripper_poses(arc.sweep(phi, start, **SWEEP), T_gn)
            yield from follow_poses(ctx.clock, arm, back, f"{where}: back the needle out")
        lift = arc.approach_poses(PRE_ARC, LIFT)[0] @ np.linalg.inv(T_gn)
        yield from move_to(ctx.clock, arm, [lift], "lift off the entry")
        self.say(f"{where}: needle backed out of {entry.name} and lifted")

    @staticmethod
    def _sweep_angle(arc, T_world_needle: np.ndarray) -> tuple[float, float]:
        """The sweep angle of the planned circle nearest the commanded needle pose, and the
        turn (deg) left between them."""
        phi, turn = arc.sweep_angle_of(T_world_needle[:3, :3])
        return phi, float(np.rad2deg(turn))
