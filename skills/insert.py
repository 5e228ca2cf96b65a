"""Skill: drive the held needle through one entry/exit pair along its planned circle.

Plans the circle of the needle radius through the pair's known port frames, checks that the
grasp leaves room for the tip to come out (the planner's grasp limit), brings the tip above and
then a few millimetres before the entry, sweeps the needle about its own centre until the tip
stands 6 mm out past the exit, and confirms from a fresh image that the tip emerged within the
SRC 2.5 mm of the exit port and stands at least 5 mm out.

Started again with the needle already at the end of its sweep (a retry after the emerged tip
was not confirmed), it only looks again, after a short back-off; ``confirm_only`` asks for
that look and fails when the needle is not there.
"""

from __future__ import annotations

import numpy as np

from suture_bt.planning import NeedleArcError, gripper_poses
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import NeedleNotSeen, TaskContext
from suture_bt.skills.grasps import JAW_CLEARANCE
from suture_bt.skills.motion import FINE, follow_poses, move_to, wait
from suture_bt.transforms import rotation_angle

#: The sweep starts with the tip this far (arc length) before the entry, and the approach
#: comes down to it along the entry normal from this height (m).
PRE_ARC, LIFT = 0.006, 0.010
#: Needle sweep limits (rad/s, rad/s²): the tip moves at up to 10 mm/s.
SWEEP = {"angular_speed": 1.0, "angular_acc": 5.0}
#: Looks at the emerged tip before giving up.
CONFIRM_LOOKS = 2
#: A needle this close to the sweep's end pose (m, deg) is already inserted; the back-off
#: before looking again (s).
AT_END_M, AT_END_DEG = 0.003, 10.0
LOOK_AGAIN_AFTER = 0.1


class Insert(Skill):
    """``arm`` (holding the needle) drives it through pair ``pair`` (1-based)."""

    name = "insert"

    def __init__(self, context: TaskContext, arm: str, pair: int, confirm_only: bool = False):
        super().__init__(context)
        self.arm_name = arm
        self.pair = pair
        self.confirm_only = confirm_only
        self.arc = None

    def program(self) -> Waiting:
        ctx = self.context
        arm = ctx.arm(self.arm_name)
        where = f"pair {self.pair}"
        T_gn = ctx.held_by(self.arm_name, where).T_tip_needle
        entry, exit_ = ctx.phantom.pair(self.pair)
        arc = ctx.plan(self.pair, where)
        try:
            arc.check_grasp(T_gn, JAW_CLEARANCE)
        except NeedleArcError as e:
            raise SkillFailure(f"{where}: {e.reason}") from None
        self.arc = arc
        self.report["arc"] = {
            "T_world_needle_entry": arc.T_world_needle_entry.tolist(),
            "port_angle_deg": float(np.rad2deg(arc.port_angle)),
            "insert_end_angle_deg": float(np.rad2deg(arc.insert_end_angle)),
        }
        at_end = self._at_sweep_end(arm, arc, T_gn)
        if at_end or self.confirm_only:
            if not at_end:
                raise SkillFailure(f"{where}: the needle is not at the end of its sweep")
            self.report["resumed"] = True
            self.say(f"{where}: needle at the end of its sweep, looking at the tip again")
            yield from wait(ctx.clock, LOOK_AGAIN_AFTER)
            yield from self._confirm(arm, exit_)
            return
        self.report["T_tip_needle"] = np.asarray(T_gn, dtype=float).tolist()  # sweep's grasp
        T_inv = np.linalg.inv(T_gn)
        lift, pre = (T @ T_inv for T in arc.approach_poses(PRE_ARC, LIFT))
        self.say(f"{where}: approaching {entry.name}")
        try:
            yield from move_to(ctx.clock, arm, [lift], "approach the entry")
            yield from move_to(ctx.clock, arm, [pre], "reach the entry", FINE, joint_ok=False)
        except SkillFailure as e:
            raise SkillFailure(
                f"{where}: entry out of {self.arm_name}'s reach: {e.reason}"
            ) from None
        self.say(f"{where}: driving the needle from {entry.name} to {exit_.name}")
        sweep = gripper_poses(
            arc.insertion(start_angle=arc.pre_insertion_angle(PRE_ARC), **SWEEP), T_gn
        )
        yield from follow_poses(ctx.clock, arm, sweep, f"{where}: drive the needle")
        yield from self._confirm(arm, exit_)

    @staticmethod
    def _at_sweep_end(arm, arc, T_gn: np.ndarray) -> bool:
        """The commanded needle stands where the insertion sweep ends (already inserted)."""
        T_now = arm.commanded_tip_world() @ T_gn
        T_end = arc.needle_pose(arc.insert_end_angle)
        dp = float(np.linalg.norm(T_now[:3, 3] - T_end[:3, 3]))
        da = float(np.rad2deg(rotation_angle(T_now[:3, :3], T_end[:3, :3])))
        return dp <= AT_END_M and da <= AT_END_DEG

    def _confirm(self, arm, exit_) -> Waiting:
        """From a fresh frame: the localiser's answer if it agrees with the arm's prediction,
        else the frame must show metal along the predicted emerged piece and none past it."""
        ctx = self.context
        reasons = []
        for _ in range(CONFIRM_LOOKS):
            predicted = ctx.predicted_needle()
            try:
                obs = ctx.sensor.observe(predicted, prior_checked=True)
                ok, detail = checks.poses_agree(obs.T_world_needle, predicted)
                if not ok:
                    raise NeedleNotSeen(f"answer disagrees with the arm: {detail}")
            except NeedleNotSeen as e:
                reasons.append(e.reason)
                seen = self._evidence(predicted, exit_)
                if seen is not None:
                    ctx.belief.T_world_needle = predicted
                    ctx.belief.stamp, ctx.belief.source = (
                        ctx.clock.now(),
                        "predicted, image-checked",
                    )
                    yield from self._judge(predicted, exit_, "predicted pose, " + seen)
                    return
                yield
                continue
            ctx.believe(obs, self.arm_name)
            yield from self._judge(obs.T_world_needle, exit_, "localised")
            return
        raise SkillFailure(f"pair {self.pair}: emerged tip not confirmed: {'; '.join(reasons)}")

    def _evidence(self, predicted: np.ndarray, exit_) -> str | None:
        """'' style summary when the last frame shows the predicted emerged tip, else None."""
        needle = self.context.needle
        ok, _, numbers = checks.tip_out_past_exit(predicted, needle, exit_)
        out = numbers.get("tip_out_mm", 0.0) * 1e-3
        if out < checks.MIN_TIP_OUT * 0.5:
            return None
        # The piece in front of the exit surface (1 mm kept clear of it), and the circle
        # continued past the tip, where no needle must be seen.
        emerged = needle.tip_angle + np.linspace(0.0, (out - 0.001) / needle.radius, 12)
        # (from 10°, 1.8 mm, past the predicted tip: the in-hand estimate may be a few
        # degrees off along the circle, and the real tip then stands that much further out)
        beyond = needle.tip_angle - np.deg2rad(np.linspace(10.0, 22.0, 8))
        try:
            on = min(self.context.sensor.support(predicted, emerged))
            off = max(self.context.sensor.support(predicted, beyond))
        except NeedleNotSeen:  # no frame to look in (the capture was lost)
            return None
        self.report["evidence"] = {"emerged_on_metal": on, "beyond_on_metal": off}
        if on >= 0.75 and off <= 0.25:
            return f"tip seen on {100 * on:.0f} % of the emerged piece, {100 * off:.0f} % past it"
        return None

    def _judge(self, T_world_needle: np.ndarray, exit_, how: str) -> Waiting:
        ok, detail, numbers = checks.tip_out_past_exit(T_world_needle, self.context.needle, exit_)
        self.report["seen"] = numbers | {"how": how}
        self.check(f"pair {self.pair}: tip out past {exit_.name}", ok, f"{detail} ({how})")
        self.say(f"pair {self.pair}: {detail}")
        yield from ()
