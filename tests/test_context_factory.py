"""What the tree is handed through ``setup(**kwargs)`` reaches no simulator object (DESIGN.md §3).

The context is walked the way skill code could walk it (attributes, slots, containers); the
oracle context, which exists only for the labelled ablation, must reach ground truth — so the
walk is shown to find it when it is there.
"""

import numpy as np
import py_trees
import pytest
from honesty_helpers import reachable_sim_objects

from suture_bt import trees
from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.runtime.context_factory import build_context
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.skills.context import TaskContext


@pytest.fixture(scope="module")
def world():
    w = World.from_scene(scene_from_dict({"needle": {"start": "in_psm2_jaw"}}))
    yield w
    w.close()


def test_the_vision_context_reaches_no_simulator_object(world):
    ctx = build_context(world)
    assert isinstance(ctx, TaskContext) and not ctx.oracle
    found = reachable_sim_objects(ctx, max_depth=10)
    assert not found, [path for path, _ in found]


def test_the_oracle_context_does_reach_ground_truth(world):
    ctx = build_context(world, oracle=True)
    assert ctx.oracle
    assert reachable_sim_objects(ctx, max_depth=10)


def test_every_node_of_every_tree_holds_only_the_context_after_setup(world):
    ctx = build_context(world)
    for name in trees.TREE_NAMES:
        py_trees.blackboard.Blackboard.clear()
        root = trees.create(name)
        tree = py_trees.trees.BehaviourTree(root)
        tree.setup(context=ctx, clock=ctx.clock, tick_dt=0.02)
        for node in root.iterate():
            found = reachable_sim_objects(vars(node), max_depth=6)
            assert not found, (name, node.name, [p for p, _ in found])


def test_trees_build_without_a_world_and_render_as_text():
    for name in trees.TREE_NAMES:
        text = py_trees.display.unicode_tree(trees.create(name))
        assert text.strip()
    with pytest.raises(ValueError, match="unknown tree"):
        trees.create("nope")


def test_the_vision_localiser_knows_the_tasks_phantom(world):
    """Only the task's phantom may hide the needle's unseen arc (the benchmark's localiser
    knows it too): a point under the block's top is inside it, one above is not."""
    ctx = build_context(world)
    tissue = ctx.sensor.localizer.tissue
    assert tissue is not None
    T = ctx.phantom.T_world_phantom
    # 30 mm beside the ridge, which stands higher than the block.
    points = [T[:3, :3] @ [0.03, 0.0, TISSUE_TOP_Z + dz] + T[:3, 3] for dz in (-0.005, 0.005)]
    assert tissue(np.array(points), margin=0.001).tolist() == [True, False]
