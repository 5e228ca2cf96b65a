"""The pulling arm's wait near the exit: where it waits, out of sight, and when it cannot."""

import numpy as np
import pytest

from suture_bt.planning import plan_needle_arc
from suture_bt.runtime.context_factory import build_context
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.skills.base import SkillStatus
from suture_bt.skills.grasps import pulling_hand, tip_goal
from suture_bt.skills.line_of_sight import intrusion
from suture_bt.skills.stand_by import STANDBY_DISTANCE, StandBy


def world_and_context(phantom=None):
    scene = scene_from_dict({"needle": {"start": "in_psm2_jaw"}, "phantom": phantom or {}})
    world = World.from_scene(scene)
    return world, build_context(world)


@pytest.mark.parametrize("pair", [1, 4])
def test_it_waits_back_from_the_planned_grasp_and_out_of_the_cameras_sight(pair):
    world, ctx = world_and_context()
    try:
        T = StandBy(ctx, "psm1", pair).standby_pose()
        arc = plan_needle_arc(*ctx.phantom.pair(pair), ctx.needle)
        grasp = tip_goal(arc.needle_pose(arc.insert_end_angle), pulling_hand(ctx.needle))
        assert np.linalg.norm(T[:3, 3] - grasp[:3, 3]) >= STANDBY_DISTANCE - 1e-9
        tip = arc.tip_position(arc.insert_end_angle)
        assert intrusion(ctx, T, ctx.arm("psm1").base_frame()[:3, 3], tip) <= 0.0
    finally:
        world.close()


def test_out_of_reach_it_fails_before_moving_with_the_reason():
    world, ctx = world_and_context({"position": [0.0, 0.0, -0.25]})
    try:
        skill = StandBy(ctx, "psm1", 2)
        skill.start()
        q0 = ctx.arm("psm1").servo.setpoint_jp().copy()
        assert skill.step(0.02) is SkillStatus.FAILURE
        assert skill.feedback.startswith("pair 2: psm1 cannot wait at the exit"), skill.feedback
        np.testing.assert_array_equal(ctx.arm("psm1").servo.setpoint_jp(), q0)
    finally:
        world.close()
