"""Keeping an arm out of the cameras' sight of the needle, from kinematics only."""

import numpy as np
import pytest

from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.runtime.context_factory import build_context
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.skills.line_of_sight import (
    CLEARANCE,
    HIDING_PLACES,
    clear_tip_pose,
    hidden_behind,
    intrusion,
    make_way,
    make_way_for,
)


@pytest.fixture(scope="module")
def ctx():
    world = World.from_scene(scene_from_dict({"needle": {"start": "in_psm2_jaw"}}))
    yield build_context(world)
    world.close()


def _scene(ctx):
    cam = ctx.camera.model.left.T_world_cam
    target = (cam @ np.array([0.0, 0.0, 0.062, 1.0]))[:3]
    rcm = ctx.arm("psm2").base_frame()[:3, 3]
    return cam, target, rcm


def test_a_tool_halfway_along_the_sight_line_intrudes_and_is_pushed_clear(ctx):
    cam, target, rcm = _scene(ctx)
    T = np.eye(4)
    T[:3, 3] = (cam @ np.array([0.0, 0.0, 0.030, 1.0]))[:3]  # on the optical axis
    assert intrusion(ctx, T, rcm, target) > 0.5 * CLEARANCE
    cleared = clear_tip_pose(ctx, T, rcm, target)
    assert cleared is not None and intrusion(ctx, cleared, rcm, target) <= 0.0
    np.testing.assert_allclose(cleared[:3, :3], T[:3, :3])  # orientation kept
    # Pushed toward the arm's own side, not through the needle.
    assert np.dot(cleared[:3, 3] - T[:3, 3], rcm - T[:3, 3]) > 0


def test_a_tool_beside_or_behind_the_target_is_clear(ctx):
    cam, target, rcm = _scene(ctx)
    beside, behind = np.eye(4), np.eye(4)
    beside[:3, 3] = (cam @ np.array([0.045, 0.0, 0.040, 1.0]))[:3]
    behind[:3, 3] = (cam @ np.array([0.0, 0.0, 0.090, 1.0]))[:3]
    assert intrusion(ctx, beside, rcm, target) == 0.0
    assert clear_tip_pose(ctx, beside, rcm, target) is None
    # Behind the needle the tip itself hides nothing (only the shaft toward the RCM is checked).
    assert intrusion(ctx, behind, rcm, target) <= intrusion(ctx, beside, rcm, target) + CLEARANCE


def test_the_tissue_hidden_under_each_arm_lies_on_the_sight_line_through_its_tool(ctx):
    T_ph = ctx.phantom.T_world_phantom
    up, top = T_ph[:3, 2], T_ph[:3, 3] + TISSUE_TOP_Z * T_ph[:3, 2]
    spots = hidden_behind(ctx, top, up)
    assert len(spots) == len(ctx.arms) * len(HIDING_PLACES)
    eye = np.mean(
        [ctx.camera.model.left.T_world_cam[:3, 3], ctx.camera.model.right.T_world_cam[:3, 3]],
        axis=0,
    )
    tips = [arm.commanded_tip_world()[:3, 3] for arm in ctx.arms.values()]
    for k, spot in enumerate(spots):
        assert abs((spot - top) @ up) < 1e-12  # on the plane
        tip = tips[k // len(HIDING_PLACES)]
        if k % len(HIDING_PLACES) == 0:  # behind the tip, on the line from the eyes through it
            u = (tip - eye) / np.linalg.norm(tip - eye)
            off = (spot - eye) - ((spot - eye) @ u) * u
            assert np.linalg.norm(off) < 1e-9 and (spot - eye) @ u > (tip - eye) @ u


def test_making_way_for_several_targets_clears_each_and_one_target_is_the_same_as_before(ctx):
    T_ph = ctx.phantom.T_world_phantom
    spots = hidden_behind(ctx, T_ph[:3, 3] + TISSUE_TOP_Z * T_ph[:3, 2], T_ph[:3, 2])
    assert len(make_way_for(ctx, spots)) == len(ctx.arms)  # every arm hides its own spots
    assert len(make_way_for(ctx, spots[:1])) == len(make_way(ctx, spots[0]))
    assert make_way_for(ctx, []) == []
