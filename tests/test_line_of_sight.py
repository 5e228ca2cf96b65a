"""Keeping an arm out of the cameras' sight of the needle, from kinematics only."""

import numpy as np
import pytest

from suture_bt.runtime.context_factory import build_context
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.skills.line_of_sight import CLEARANCE, clear_tip_pose, intrusion


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
