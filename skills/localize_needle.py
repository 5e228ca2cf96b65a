"""Skill: localise the needle (free, resting or held) and adopt the estimate as the belief.

A held needle is first presented (:mod:`presentation`): the holding arm turns the arc toward the
cameras, because at the Task 3 start pose it is too close and edge-on to localise. Each answer
must agree with the task: a held needle's wire passes the holder's pinch point. A refusal or a
disagreement moves on to the next presentation pose; after the last one the skill fails with
the reasons it collected. Output: the world pose, its predicted spread and (held) the needle in
the holder's tip frame.
"""

from __future__ import annotations

import numpy as np

from suture_bt.perception.in_hand import estimate_in_hand
from suture_bt.skills import presentation
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import NeedleNotSeen, NeedleObservation, TaskContext
from suture_bt.skills.motion import move_to

#: A held needle's wire must pass this close to the holder's pinch point (m): the jaw grips
#: the wire; the margin covers the tip-pose error of an arm that is not yet calibrated.
HOLD_TOLERANCE_CALIBRATED = 0.002
HOLD_TOLERANCE_UNCALIBRATED = 0.012
#: Presentation poses tried before giving up.
MAX_PRESENTATIONS = 3


class LocalizeNeedle(Skill):
    """Localise the needle; ``holder`` names the arm holding it (None: free or resting)."""

    name = "localize needle"

    def __init__(self, context: TaskContext, holder: str | None = None, present: bool = True):
        super().__init__(context)
        self.holder = holder
        self.present = present

    def program(self) -> Waiting:
        ctx = self.context
        reasons: list[str] = []
        if self.holder is None or not self.present:
            obs = self._look(reasons)
            if obs is not None:
                self._adopt(obs)
                return
            if self.holder is None:
                raise SkillFailure(f"needle not localised: {'; '.join(reasons)}")
        arm = ctx.arm(self.holder)
        poses, why = presentation.choose(ctx, arm)
        if not poses:
            raise SkillFailure(f"{arm.name} has no reachable presentation pose ({why[:1]})")
        self.report["presentation_poses"] = [T.tolist() for T in poses]
        for i, T in enumerate(poses[:MAX_PRESENTATIONS]):
            self.say(f"presenting the needle held by {arm.name} ({i + 1}/{len(poses)})")
            yield from move_to(ctx.clock, arm, [T], "present the needle")
            obs = self._look(reasons)
            if obs is not None:
                self._adopt(obs)
                return
        raise SkillFailure(f"needle held by {arm.name} not localised: {'; '.join(reasons)}")

    def _look(self, reasons: list[str]) -> NeedleObservation | None:
        ctx = self.context
        previous = ctx.predicted_needle()
        try:
            obs = ctx.sensor.observe(previous)
        except NeedleNotSeen as e:
            reasons.append(e.reason)
            self.report.setdefault("refusals", []).append(e.reason)
            return None
        if self.holder is not None:
            arm = ctx.arm(self.holder)
            tol = HOLD_TOLERANCE_CALIBRATED if arm.calibrated else HOLD_TOLERANCE_UNCALIBRATED
            tip = arm.tip_world()
            grip = estimate_in_hand(
                obs.T_world_needle,
                np.linalg.inv(arm.base_frame()) @ tip,
                arm.base_frame(),
                ctx.needle,
                max_jaw_distance=tol,
            )
            ok = grip.plausible
            detail = (
                f"wire {grip.jaw_distance * 1e3:.1f} mm from {arm.name}'s pinch point "
                f"(limit {tol * 1e3:.0f} mm)"
            )
            self.report["checks"].append(
                {"check": "held by " + arm.name, "ok": ok, "detail": detail}
            )
            if not ok:
                reasons.append(f"answer disagrees with the grasp: {detail}")
                return None
        return obs

    def _adopt(self, obs: NeedleObservation) -> None:
        belief = self.context.believe(obs, self.holder)
        self.report["estimate"] = {
            "T_world_needle": obs.T_world_needle.tolist(),
            "angle_std_deg": obs.angle_std_deg,
            "position_std_mm": obs.position_std_mm,
            "source": obs.source,
            "holder": self.holder,
        }
        where = f"held by {self.holder}" if self.holder else "free"
        self.say(
            f"needle {where} at {np.round(1e3 * belief.T_world_needle[:3, 3], 1)} mm "
            f"(spread {obs.angle_std_deg:.2f}°)"
        )
