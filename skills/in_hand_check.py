"""Skill: before an insertion, look at the held needle over the entry: has it slipped?

A slip turns the needle in the jaw or slides it along its wire; the joints cannot tell, only
the images can. The inserting arm brings the needle to where the insertion's approach starts
(lifted above the entry, the pose the insertion goes to first), the needle is localised there
(presented to the cameras only when that view is refused) and the estimate is compared with
the pose the belief's in-hand transform predicts. Agreeing (``checks.poses_agree``), the
in-hand estimate stands unchanged; disagreeing, a second look from higher up decides (agreeing
with the grasp, the first answer was wrong and the grasp stands); else the needle slipped: the
fresh estimate becomes
the in-hand transform and the report says ``slipped`` (the tree then checks the planner's
grasp limit on it and re-grasps when it leaves the tip too little room). A needle seen off the
calibrated arm's pinch point cannot have slipped (a slip keeps the wire between the blades):
the arm is not where its calibration says, its offset drifted: once a second view from
higher up says so too (one look 1.6 mm off the pinch point ended a report trial in a needless
recalibration), the calibration is marked lost and the skill fails saying so (the tree
recalibrates). A view whose answer the held-by test
refuses (the wire off the pinch point) is that evidence already: the needle is then not
presented (a drifted arm believed calibrated presented it into the ridge). A needle that no
view localises keeps its estimate, and the report says it was not re-checked.
"""

from __future__ import annotations

import numpy as np

from suture_bt.perception.in_hand import estimate_in_hand
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import TaskContext
from suture_bt.skills.grasps import held_arc_angle
from suture_bt.skills.insert import LIFT, PRE_ARC, approach_path
from suture_bt.skills.line_of_sight import make_way
from suture_bt.skills.localize_needle import LocalizeNeedle
from suture_bt.skills.motion import feasible, move_to, together
from suture_bt.skills.needle_sensor import in_working_range
from suture_bt.transforms import invert, rotation_angle

#: A calibrated arm whose held wire is seen this far from its pinch point, and the needle this
#: far from the prediction, has drifted (m): a slip turns and slides the needle in the jaw but
#: keeps the wire between the blades. (No-fault checks: 0.3-0.6 mm from the prediction.)
DRIFT_JAW, DRIFT_POSITION = 0.0012, 0.0015
#: A slip turns the needle about an axis through the held point (the jaw's closing axis, on
#: which the needle's centre lies, or the jaw's own axis) or slides it along its circle about
#: its centre: it moves the centre by at most a radius times the turn. A needle moved with
#: less than this share of that turn moved with the jaw: a drift, wherever along the wire it
#: went (a move along the wire leaves the wire between the blades).
DRIFT_TURN_SHARE = 0.5
#: A second view is taken this far above the first (m), before the needle is presented (a
#: drifted arm, still believed calibrated, presented it 1.7-2.5 mm into the ridge); a drifted
#: arm rises as far before the handover that empties its jaw (else 1.3 mm into the flank).
RISE = 0.020


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
            approach = move_to(ctx.clock, arm, approach_path(ctx, arm, lift), "approach the entry")
            yield from together(approach, *make_way(ctx, (lift @ T_gn)[:3, 3], self.arm_name))
        except SkillFailure as e:
            raise SkillFailure(
                f"{where}: entry out of {self.arm_name}'s reach: {e.reason}"
            ) from None
        seen, off_grasp = yield from self._look()
        predicted = arm.tip_world() @ T_gn  # where the arm stands when it looked
        if seen is None and off_grasp and arm.calibrated:
            yield from self._rise()
            self._drifted(arm, kept, f"seen off its pinch point: {off_grasp[-1]}")
        if seen is None:
            ctx.belief = kept
            self.report["checked"] = False
            self.say(f"{where}: in-hand pose not re-checked (no view localised the needle)")
            return
        ok, detail = checks.poses_agree(seen.T_world_needle, predicted)
        drift = self._drift_seen(arm, seen.T_world_needle, predicted, record=True)
        if drift:
            yield from self._rise()
            again = yield from self._look_again()
            if again is None or self._drift_seen(arm, again.T_world_needle, arm.tip_world() @ T_gn):
                self._drifted(arm, kept, drift)
            ctx.belief = kept  # a second view puts the wire back between the blades
            self.report.update(checked=True, slipped=False, drift_refuted=drift)
            self.say(f"{where}: a second look refutes a drift ({drift}): in-hand pose kept")
            return
        if not ok and not (yield from self._slip_confirmed(arm, kept, seen)):
            ctx.belief = kept  # the first answer was wrong: the grasp stands
            self.report.update(checked=True, slipped=False, refuted=detail)
            self.say(f"{where}: a second look refutes the first ({detail}): in-hand pose kept")
            return
        seen = ctx.belief
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

    def _drift_seen(
        self, arm, T_seen: np.ndarray, predicted: np.ndarray, record: bool = False
    ) -> str:
        """Why a needle seen at ``T_seen`` (the belief predicting ``predicted``) says the
        calibrated arm drifted ('' when it does not): off the prediction and off the pinch
        point, or moved with the jaw rather than turned in it."""
        jaw = self._jaw_distance(arm, T_seen)
        dp = float(np.linalg.norm(T_seen[:3, 3] - predicted[:3, 3]))
        if record:
            self.report.update(jaw_distance_mm=1e3 * jaw, off_prediction_mm=1e3 * dp)
        turn = rotation_angle(T_seen[:3, :3], predicted[:3, :3])
        moved_with_jaw = turn < DRIFT_TURN_SHARE * dp / self.context.needle.radius
        if not arm.calibrated or dp <= DRIFT_POSITION or not (jaw > DRIFT_JAW or moved_with_jaw):
            return ""
        _, detail = checks.poses_agree(T_seen, predicted)
        return f"wire {1e3 * jaw:.1f} mm from its pinch point, {detail}"

    def _look_again(self) -> Waiting:
        """A second, independent view of the held needle from here (presented when out of
        the localiser's range or refused): the fresh belief, or None."""
        ctx = self.context
        for present in (False, True):
            if not present and not in_working_range(ctx.camera, ctx.predicted_needle()):
                continue
            try:
                yield from self.run(LocalizeNeedle(ctx, self.arm_name, present=present))
                return ctx.belief
            except SkillFailure as e:
                self.report.setdefault("refusals", []).append(e.reason)
        return None

    def _jaw_distance(self, arm, T_world_needle: np.ndarray) -> float:
        """How far (m) the seen wire passes from the pinch point of the calibrated arm."""
        base = arm.base_frame()
        tip = invert(base) @ arm.tip_world()
        return estimate_in_hand(T_world_needle, tip, base, self.context.needle).jaw_distance

    def _drifted(self, arm, kept, seen: str) -> None:
        """The needle is not where the arm's calibration puts its jaws: the offset drifted.
        The calibration is marked lost (the tree recalibrates); the skill fails saying so
        (the arm has risen from the entry first: its needle hangs lower than believed)."""
        self.context.belief = kept
        arm.calibrated = False
        self.report.update(checked=True, drift=True, detail=seen)
        raise SkillFailure(
            f"pair {self.pair}: {arm.name}'s calibration no longer holds ({seen}): the needle "
            f"cannot have left its jaws, so its joint offset drifted"
        )

    def _slip_confirmed(self, arm, kept, seen) -> Waiting:
        """A slip seen in one look is looked at again from ``RISE`` higher before it is
        believed: one confident wrong answer (a twin 7 mm / 42° off, on a benchmark scene)
        taken as a slip drove the next insertion 10 mm beside its entry. False when the
        second answer (risen, else presented) agrees with the kept grasp and not with the
        first; True otherwise (it agrees with the first, with neither, or no view answers: the
        first look stands, or the second with neither). The belief is left at the answer that
        stands."""
        ctx = self.context
        yield from self._rise()
        if (yield from self._look_again()) is None:  # risen, else presented to the cameras
            ctx.belief = seen
            return True
        T_tip = arm.tip_world()
        second = ctx.belief.T_world_needle
        like_first, _ = checks.poses_agree(second, T_tip @ seen.T_tip_needle)
        like_kept, _ = checks.poses_agree(second, T_tip @ kept.T_tip_needle)
        self.report["second_look"] = dict(agrees_with_first=like_first, agrees_with_grasp=like_kept)
        if like_first:
            ctx.belief = seen
        return not (like_kept and not like_first)

    def _rise(self) -> Waiting:
        """Straight up ``RISE`` along the phantom's up axis (as far as the arm reaches)."""
        ctx = self.context
        arm = ctx.arm(self.arm_name)
        T = arm.commanded_tip_world()
        T[:3, 3] += RISE * ctx.phantom.T_world_phantom[:3, 2]
        if not feasible(arm, [T]):
            yield from move_to(ctx.clock, arm, [T], "rise from the entry")

    def _look(self) -> Waiting:
        """The fresh belief from this view, a risen one, else a presentation (None: refused),
        and the refused answers' distances from the pinch point (a needle seen off it)."""
        ctx = self.context
        off_grasp = []
        for i, present in enumerate((False, False, True)):
            if i == 1:  # a second view, risen from the entry, before presenting it
                yield from self._rise()
            if not present and not in_working_range(ctx.camera, ctx.predicted_needle()):
                self.report.setdefault("skipped_looks", []).append(
                    "needle nearer the cameras than the localiser's range"
                )
                continue
            look = LocalizeNeedle(ctx, self.arm_name, present=present)
            try:
                yield from self.run(look)
                return ctx.belief, off_grasp
            except SkillFailure as e:
                self.report.setdefault("refusals", []).append(e.reason)
                refused = [c for c in look.report.get("checks", []) if not c["ok"]]
                off_grasp += [c["detail"] for c in refused if "held by" in c["check"]]
                if off_grasp:  # seen, but off the pinch point: no need to present it
                    break
        return None, off_grasp
