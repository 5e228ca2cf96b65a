"""Grasps of a resting needle: the straight-down grasp first, then the same hand with its jaws
turned about the wire (for a wrist that cannot reach the straight one), each still closing
across the wire and going no deeper into the tissue than allowed."""

from types import SimpleNamespace

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z, PhantomModel
from suture_bt.skills.grasps import GRASP_DEPTH, hand, tip_goal
from suture_bt.skills.resting_grasp import (
    APPROACH_TILTS,
    TILT_EXTRA_DEPTH,
    jaw_heights,
    resting_grasps,
    tilted_about_wire,
)
from suture_bt.transforms import make_transform

NEEDLE = NeedleModel()


def _flat(z_up: bool = True) -> np.ndarray:
    """A needle lying flat on the tissue top (z up, or turned over)."""
    R = np.eye(3) if z_up else np.diag([1.0, -1.0, -1.0])
    return make_transform(R, np.array([-0.02, 0.03, TISSUE_TOP_Z + 0.00036]))


def test_turning_about_the_wire_keeps_the_wire_and_turns_the_approach():
    a = 2.0
    straight = hand(NEEDLE, a)
    wire = NEEDLE.point_at(np.array([a]))[0]
    for tilt in (np.deg2rad(15.0), np.deg2rad(-30.0)):
        T = tilted_about_wire(straight, tilt)
        # the held wire point stays GRASP_DEPTH behind the tip, the wire along tip x
        assert np.allclose(T[:3, :3] @ wire + T[:3, 3], [0.0, 0.0, -GRASP_DEPTH])
        tangent_tip = T[:3, :3] @ np.array([np.sin(a), -np.cos(a), 0.0])
        assert abs(abs(tangent_tip[0]) - 1.0) < 1e-9
        # the approach (tip z, seen from the needle) turned by the tilt
        z_before, z_after = np.linalg.inv(straight)[:3, 2], np.linalg.inv(T)[:3, 2]
        assert np.isclose(np.degrees(np.arccos(z_before @ z_after)), abs(np.degrees(tilt)))


def test_a_flat_needle_is_offered_the_straight_grasp_first_then_turned_ones():
    ctx = SimpleNamespace(phantom=PhantomModel(), needle=NEEDLE)
    for z_up, name in ((True, "driving"), (False, "turned over")):
        T_world = _flat(z_up)
        grasps = resting_grasps(ctx, T_world, 2.0)
        assert grasps[0].hand == name
        turned = grasps[1:]
        assert 1 <= len(turned) <= len(APPROACH_TILTS)
        floor = jaw_heights(ctx, T_world, grasps[0].T_tip_needle)[1] - TILT_EXTRA_DEPTH
        for g in turned:
            assert g.hand.startswith(f"{name}, jaws turned")
            assert jaw_heights(ctx, T_world, g.T_tip_needle)[1] >= floor
            # the jaws still come from above: tip z points down
            assert tip_goal(T_world, g.T_tip_needle)[2, 2] < -0.8
