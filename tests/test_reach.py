"""The throw's reach check: IK over every planned pose of a pair, before anything moves."""

import numpy as np
import pytest

from suture_bt.runtime.context_factory import build_context
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.skills.reach import pair_reach


def context_for(phantom: dict):
    scene = scene_from_dict({"needle": {"start": "in_psm2_jaw"}, "phantom": phantom})
    world = World.from_scene(scene)
    return world, build_context(world)


@pytest.mark.parametrize(
    "phantom",
    [{}, {"position": [0.02, -0.02, -0.01]}, {"rpy": [0.0, 0.0, float(np.deg2rad(15.0))]}],
    ids=["default", "moved", "turned"],
)
def test_every_pair_is_in_reach_of_both_arms_on_a_phantom_near_the_default(phantom):
    world, ctx = context_for(phantom)
    try:
        assert [pair_reach(ctx, p, "psm2", "psm1") for p in (1, 2, 3, 4)] == [""] * 4
    finally:
        world.close()


def test_a_phantom_far_below_the_arms_is_out_of_psm2s_reach_at_the_first_entry():
    world, ctx = context_for({"position": [0.0, 0.0, -0.25]})
    try:
        why = pair_reach(ctx, 1, "psm2", "psm1")
        assert why.startswith("pair 1: entry out of PSM2's reach at entry1 (goal 1:"), why
        assert "joint 3" in why  # the insertion joint runs out
    finally:
        world.close()


def test_a_phantom_moved_aside_loses_only_the_far_pair():
    world, ctx = context_for({"position": [0.0, -0.06, 0.0]})
    try:
        answers = [pair_reach(ctx, p, "psm2", "psm1") for p in (1, 2, 3, 4)]
        assert answers[:3] == ["", "", ""]
        assert answers[3].startswith("pair 4: entry out of PSM2's reach at entry4"), answers[3]
    finally:
        world.close()


def test_a_phantom_turned_away_puts_an_exit_out_of_psm1s_reach():
    world, ctx = context_for({"rpy": [0.0, 0.0, 0.6]})
    try:
        why = pair_reach(ctx, 1, "psm2", "psm1")
        assert why.startswith("pair 1: exit out of PSM1's reach at exit1"), why
    finally:
        world.close()


def test_a_phantom_moved_toward_the_cameras_puts_the_first_exit_out_of_view():
    # Moved 18 mm toward the cameras, 15 mm aside, 4 mm down, tilted 3° and turned -10°: the
    # arms reach pair 1, but exit 1 falls below the images' bottom edge, where no look could
    # confirm the emerged tip (the insertion was made, then backed out through the exit).
    world, ctx = context_for({"position": [-0.015, 0.018, -0.004], "rpy": [0.0, 0.0524, -0.1745]})
    try:
        answers = [pair_reach(ctx, p, "psm2", "psm1") for p in (1, 2, 3, 4)]
        assert answers[0].startswith("pair 1: exit1 out of the left camera's view"), answers[0]
        assert "of 1920×1080" in answers[0]
        assert answers[1:] == ["", "", ""]
    finally:
        world.close()
