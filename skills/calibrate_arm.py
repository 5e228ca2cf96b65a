"""Skill: calibrate one arm's hidden joint offset and install Δq̂ in its PI servo.

Wraps the stepwise :class:`~suture_bt.calibration.Calibration` (calibration pose, one image,
keypoint CNN + MLP). The jaw must be empty (the pose opens it, and the regressor was trained
on an empty jaw), so the skill fails with that reason when the belief says the arm holds the
needle. A lost frame (:class:`FrameLost` from the calibration's capture) is captured again
after a short back-off in simulated time, up to ``MAX_LOST_FRAMES`` in a row; then the skill
fails with that reason. In the oracle ablation the true offset is installed instead, labelled
in the report.
"""

from __future__ import annotations

import numpy as np

from suture_bt.calibration.calibrate import Calibration
from suture_bt.calibration.calibration_pose import CALIBRATION_POSES
from suture_bt.interfaces import FrameLost
from suture_bt.kinematics import forward_kinematics
from suture_bt.skills import presentation
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import TaskContext
from suture_bt.skills.line_of_sight import CLEARANCE, intrusion
from suture_bt.skills.motion import move_to, wait
from suture_bt.skills.tip_uncertainty import worst_offset_displacement

#: Lost frames in a row before the calibration gives up, and the back-off between tries (s).
MAX_LOST_FRAMES = 3
FRAME_BACK_OFF = 0.1


#: Joint speed of the move to the calibration pose (rad/s; the insertion joint a tenth in
#: m/s; smoothstep, so the peak is 1.5 times this): the arm settles before the image is taken.
APPROACH_SPEED = 1.0


class CalibrateArm(Skill):
    """Calibrate ``arm`` (psm1 or psm2)."""

    name = "calibrate arm"

    def __init__(self, context: TaskContext, arm: str):
        super().__init__(context)
        self.arm_name = arm

    def program(self) -> Waiting:
        ctx = self.context
        handle = ctx.arm(self.arm_name)
        if ctx.belief is not None and ctx.belief.holder == self.arm_name:
            raise SkillFailure(f"{self.arm_name} holds the needle: calibration needs an empty jaw")
        yield from self._holder_makes_way()
        self.say(f"calibrating {self.arm_name}: moving to the calibration pose")
        cal = Calibration(handle.arm, ctx.camera, handle.servo, speed=APPROACH_SPEED)
        cal.start()
        lost: list[str] = []
        while cal.phase not in ("done", "failed"):
            yield
            try:
                cal.step(self.dt)
            except FrameLost as e:  # the pose is held; the next step captures again
                lost.append(f"{e.reason} at {e.stamp:.2f} s")
                self.report["frames_lost"] = list(lost)
                if len(lost) >= MAX_LOST_FRAMES:
                    raise SkillFailure(
                        f"calibration of {self.arm_name} failed: "
                        f"{len(lost)} frames lost in a row ({lost[-1]})"
                    ) from None
                self.say(f"calibrating {self.arm_name}: frame lost ({len(lost)}), capturing again")
                yield from wait(ctx.clock, FRAME_BACK_OFF)
                continue
            lost.clear()  # only losses in a row count
            self.say(f"calibrating {self.arm_name}: {cal.phase}")
        if cal.failure is not None:
            raise SkillFailure(f"calibration of {self.arm_name} failed: {cal.failure}")
        dq = np.asarray(cal.result.offset, dtype=float)[:3]
        if ctx.offset_oracle is not None:
            dq = np.asarray(ctx.offset_oracle(self.arm_name), dtype=float)[:3]
            handle.servo.set_offset_estimate(dq)
            self.report["oracle"] = True
        handle.calibrated = True
        handle.possible_offsets = None  # what earlier looks left is superseded
        handle.offset_estimate = dq.copy()
        self.report["offset_estimate"] = [float(dq[0]), float(dq[1]), float(dq[2])]
        self.say(
            f"{self.arm_name} calibrated: Δq̂ = ({np.rad2deg(dq[0]):+.2f}°, "
            f"{np.rad2deg(dq[1]):+.2f}°, {1e3 * dq[2]:+.2f} mm)"
        )

    def _holder_makes_way(self) -> Waiting:
        """An arm holding the needle (and the needle) that stands in the cameras' sight of this
        arm's jaw at the calibration pose (which may lie as far from its kinematic place as the
        offset bound allows) moves to a presentation pose clear of it: a presentation keeps
        the needle clear of the tissue. Nothing moves when it is clear, or no such pose is."""
        ctx = self.context
        b = ctx.belief
        if b is None or b.holder is None or b.holder == self.arm_name:
            return
        holder = ctx.arm(b.holder)
        q_cal = CALIBRATION_POSES[self.arm_name]
        jaw = (ctx.arm(self.arm_name).base_frame() @ forward_kinematics(q_cal))[:3, 3]
        spread = CLEARANCE + worst_offset_displacement(q_cal)
        rcm = holder.base_frame()[:3, 3]

        def clear(T) -> str:
            return "in the sight of the jaw" if intrusion(ctx, T, rcm, jaw, spread) > 0 else ""

        if not clear(holder.commanded_tip_world()):
            return
        poses, _ = presentation.choose(ctx, holder, clear)
        if poses:
            self.say(f"calibrating {self.arm_name}: {holder.name} takes the needle out of sight")
            path = presentation.lifted_first(ctx, holder, poses[0])
            yield from move_to(ctx.clock, holder, path, "out of the cameras' sight")
