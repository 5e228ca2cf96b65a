"""Recovery skills between attempts: an arm that closed empty opens and backs off."""

import numpy as np

from suture_bt.kinematics import JOINT_LIMITS
from suture_bt.runtime.context_factory import build_context
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.skills.base import SkillStatus
from suture_bt.skills.grasps import backed_off
from suture_bt.skills.motion import feasible
from suture_bt.skills.recover import BACK_OFF, OpenAndBackOff


def run(world, skill, limit_s: float = 5.0) -> SkillStatus:
    skill.start()
    for _ in range(int(limit_s / 0.02)):
        status = skill.step(0.02)
        if status is not SkillStatus.RUNNING:
            return status
        world.step(0.02)
    return SkillStatus.RUNNING


def test_with_the_back_off_pose_out_of_reach_the_arm_draws_back_along_its_shaft():
    # A campaign trial's taker stood with its wrist yaw near the limit; backing off 10 mm along
    # its jaws needed 1.53 rad of yaw (limit 1.48) and the recovery ended the run there.
    world = World.from_scene(scene_from_dict({"needle": {"start": "in_psm2_jaw"}}))
    try:
        ctx = build_context(world)
        arm = ctx.arm("psm1")
        q = arm.servo.setpoint_jp()
        for yaw in (JOINT_LIMITS[5, 1] - 0.01, JOINT_LIMITS[5, 0] + 0.01):
            q[5] = yaw
            arm.servo.servo_jp(q)
            if feasible(arm, [backed_off(arm.commanded_tip_world(), BACK_OFF)]):
                break
        else:
            raise AssertionError("no wrist yaw puts the back-off pose out of reach")
        for _ in range(50):
            world.step(0.02)
        skill = OpenAndBackOff(ctx, "psm1")
        assert run(world, skill) is SkillStatus.SUCCESS, skill.feedback
        assert "wrist_yaw" in skill.report["retracted_instead"]
        q_after = arm.servo.setpoint_jp()
        assert q_after[2] == np.float64(max(q[2] - BACK_OFF, JOINT_LIMITS[2, 0]))
        np.testing.assert_allclose(np.delete(q_after, 2), np.delete(q, 2), atol=1e-12)
        assert arm.jaw_angle() > 0.7
    finally:
        world.close()
