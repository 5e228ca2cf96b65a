"""Skill: drive the held needle through one entry/exit pair along its planned circle.

Plans the circle of the needle radius through the pair's known port frames, checks that the
grasp leaves room for the tip to come out (the planner's grasp limit), brings the tip above and
then a few millimetres before the entry, sweeps the needle about its own centre until the tip
stands 6 mm out past the exit, and confirms from a fresh image that the tip emerged within the
SRC 2.5 mm of the exit port and stands at least 5 mm out: from the localiser's answer, or,
when it refuses the mostly buried needle, from the tip read in the frame near the predicted
pose (:mod:`tip_reading`). A needle seen crossing the exit but short of the rule is driven on
along its own circle as far as the grasp allows and looked at again (backing an emerged tip
out would re-enter the tissue at the exit).

Started again with the needle already at the end of its sweep (a retry after the emerged tip
was not confirmed), it only looks again, after a short back-off; ``confirm_only`` asks for
that look and fails when the needle is not there. Started with the needle held part way
along the circle (taken again where it hung after a drop, :mod:`take_hanging`), it sweeps on
from there along the needle's own circle and confirms.
"""

from __future__ import annotations

import numpy as np

from suture_bt.perception.in_hand import JAW_POINT_IN_TIP
from suture_bt.planning import NeedleArcError, gripper_poses
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import NeedleNotSeen, NeedleObservation, TaskContext
from suture_bt.skills.grasps import JAW_CLEARANCE
from suture_bt.skills.motion import FINE, feasible, follow_poses, move_to, wait
from suture_bt.skills.tip_reading import read_tip
from suture_bt.transforms import invert, rotation_angle

#: The sweep starts with the tip this far (arc length) before the entry, and the approach
#: comes down to it along the entry normal from this height (m).
PRE_ARC, LIFT = 0.006, 0.010
#: Height above the approach pose (m) at which the arm turns to it before coming down.
TURN_HEIGHT = 0.015
#: A tip this near the lift pose (m, deg) goes straight to it: nothing to turn on the way.
NEAR_LIFT = (0.005, 10.0)
#: Needle sweep limits (rad/s, rad/s²): the tip moves at up to 13 mm/s (1.6 rad/s raised the
#: peak tissue strain by ~60 % over 1.0 rad/s on dev trials; 1.3 keeps most of the time saved).
SWEEP = {"angular_speed": 1.3, "angular_acc": 6.5}
#: Looks at the emerged tip before giving up (one may follow a drive-on).
CONFIRM_LOOKS = 3
#: A needle seen with less than ``DRIVE_ON_BELOW`` of tip out (m; the SRC's 5 mm and half a
#: millimetre of estimate error) is driven on by at least ``DRIVE_ON_DEG`` (or to the planned
#: end), as far as its grasp allows, when that leaves ``MIN_DRIVE_ON_DEG`` to go.
DRIVE_ON_BELOW = 0.0055
DRIVE_ON_DEG, MIN_DRIVE_ON_DEG = 8.0, 1.0
#: A needle this close to the sweep's end pose (m, deg) is already inserted; the back-off
#: before looking again (s).
AT_END_M, AT_END_DEG = 0.003, 10.0
LOOK_AGAIN_AFTER = 0.1


def approach_path(ctx: TaskContext, arm, lift: np.ndarray) -> list[np.ndarray]:
    """Waypoints to an entry's lift pose: turned to its orientation ``TURN_HEIGHT`` above it
    first, then down (a joint move straight from a presentation swings the needle low over the
    ridge); straight there when the high pose is out of reach, or when the arm is nearly
    there already (the in-hand check leaves it at the lift pose: the detour cost 0.4 s)."""
    dp, da = checks.pose_difference(arm.commanded_tip_world(), lift)
    if dp <= NEAR_LIFT[0] and da <= NEAR_LIFT[1]:
        return [lift]
    high = lift.copy()
    high[:3, 3] += TURN_HEIGHT * ctx.phantom.T_world_phantom[:3, 2]
    return [lift] if feasible(arm, [high, lift]) else [high, lift]  # feasible: "" = reachable


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
        self.report["pair"] = self.pair
        self.report["arc"] = {
            "T_world_needle_entry": arc.T_world_needle_entry.tolist(),
            "port_angle_deg": float(np.rad2deg(arc.port_angle)),
            "insert_end_angle_deg": float(np.rad2deg(arc.insert_end_angle)),
        }
        phi = self._part_way(arc, ctx.predicted_needle())
        at_end = self._at_sweep_end(arm, arc, T_gn) or (
            phi is not None and phi >= arc.insert_end_angle
        )
        if at_end or self.confirm_only:
            if not at_end:
                raise SkillFailure(f"{where}: the needle is not at the end of its sweep")
            self.report["resumed"] = True
            self.say(f"{where}: needle at the end of its sweep, looking at the tip again")
            yield from wait(ctx.clock, LOOK_AGAIN_AFTER)
            yield from self._confirm(arm, exit_)
            return
        self.report["T_tip_needle"] = np.asarray(T_gn, dtype=float).tolist()  # sweep's grasp
        if phi is not None:
            yield from self._drive_on_from(arm, phi, exit_)
            return
        T_inv = np.linalg.inv(T_gn)
        lift, pre = (T @ T_inv for T in arc.approach_poses(PRE_ARC, LIFT))
        path = approach_path(ctx, arm, lift)
        self.say(f"{where}: approaching {entry.name}")
        try:
            yield from move_to(ctx.clock, arm, path, "approach the entry")
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

    def _part_way(self, arc, T_now: np.ndarray) -> float | None:
        """The sweep angle of a needle held on the planned circle with its tip past the entry
        (taken again where it hung after a drop, or further back after a short sweep), else
        None; at or past the sweep's end it is only looked at (and driven on when short)."""
        why_not, phi = checks.on_planned_circle(arc, T_now, self.pair)
        return None if why_not or phi <= 0.0 else float(phi)

    def _drive_on_from(self, arm, phi: float, exit_) -> Waiting:
        """Sweep a needle taken again part way on about its own centre (it runs in its own
        track) to the planned end, and confirm the emerged tip."""
        ctx = self.context
        arc, T_gn = self.arc, ctx.belief.T_tip_needle
        self.report["resumed_from_deg"] = float(np.rad2deg(phi))
        self.say(
            f"pair {self.pair}: needle part way through, driving it on from {np.rad2deg(phi):.0f}°"
        )
        T_seen = ctx.predicted_needle()
        on = arc.insertion(start_angle=phi, **SWEEP)
        on = gripper_poses(on.transformed(T_left=T_seen @ invert(arc.needle_pose(phi))), T_gn)
        yield from follow_poses(ctx.clock, arm, on, f"pair {self.pair}: drive the needle on")
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
        else the tip read from the frame along the predicted circle (:meth:`_tip_reading`).
        A reading short of the exit rule is driven on along the arc as far as its grasp
        allows, and looked at again."""
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
                T_jaw = arm.tip_world()
                jaw = (T_jaw[:3, :3] @ JAW_POINT_IN_TIP + T_jaw[:3, 3], T_jaw[:3, 1])
                reading = read_tip(ctx.sensor, ctx.needle, predicted, exit_, jaw)
                if reading is None:
                    reasons.append("no emerged tip read near the predicted pose")
                    yield
                    continue
                self.report["evidence"] = {
                    "turn_deg": reading.turn_deg,
                    "pivot_deg": reading.pivot_deg,
                    "emerged_on_metal": reading.on,
                    "beyond_on_metal": reading.off,
                }
                T_seen, how = reading.T_world_needle, reading.describe()
                ctx.believe(
                    NeedleObservation(T_seen, ctx.clock.now(), 0.0, 0.0, "image-read tip"),
                    self.arm_name,
                )
                if (yield from self._drive_on(arm, T_seen, exit_)):
                    continue  # look at where the needle is now
                yield from self._judge(T_seen, exit_, how)
                return
            ctx.believe(obs, self.arm_name)
            if (yield from self._drive_on(arm, obs.T_world_needle, exit_)):
                continue
            yield from self._judge(obs.T_world_needle, exit_, "localised")
            return
        raise SkillFailure(f"pair {self.pair}: emerged tip not confirmed: {'; '.join(reasons)}")

    def _drive_on(self, arm, T_seen: np.ndarray, exit_) -> Waiting:
        """Sweep the needle on about its own centre (it runs in its own track) by at least
        ``DRIVE_ON_DEG`` or to the planned end, as far as the reading's grasp allows, when the
        seen tip crosses the exit within the rule but stands less than ``DRIVE_ON_BELOW`` out
        (once per insertion); True if it moved."""
        _, _, seen = checks.tip_out_past_exit(T_seen, self.context.needle, exit_)
        crossing = seen and seen["lateral_mm"] <= 1e3 * checks.MAX_LATERAL
        if not crossing or seen["tip_out_mm"] >= 1e3 * DRIVE_ON_BELOW:
            return False
        if "driven_on_deg" in self.report:
            return False
        arc = self.arc
        T_gn = self.context.belief.T_tip_needle
        phi, _ = arc.sweep_angle_of(T_seen[:3, :3])
        end = max(arc.insert_end_angle, phi + np.deg2rad(DRIVE_ON_DEG))
        end = min(end, arc.grasp_limit_angle(T_gn, JAW_CLEARANCE))
        if end - phi < np.deg2rad(MIN_DRIVE_ON_DEG):
            return False
        self.report["driven_on_deg"] = float(np.rad2deg(end - phi))
        self.say(
            f"pair {self.pair}: tip short, driving on {np.rad2deg(end - phi):.1f}° along its arc"
        )
        # The planned sweep's timing and turns, carried onto the seen needle's own circle.
        on = arc.sweep(phi, end, **SWEEP).transformed(T_left=T_seen @ invert(arc.needle_pose(phi)))
        on = gripper_poses(on, T_gn)
        yield from follow_poses(self.context.clock, arm, on, f"pair {self.pair}: drive on")
        return True

    def _judge(self, T_world_needle: np.ndarray, exit_, how: str) -> Waiting:
        ok, detail, numbers = checks.tip_out_past_exit(T_world_needle, self.context.needle, exit_)
        self.report["seen"] = numbers | {"how": how}
        self.check(f"pair {self.pair}: tip out past {exit_.name}", ok, f"{detail} ({how})")
        self.say(f"pair {self.pair}: {detail}")
        yield from ()
