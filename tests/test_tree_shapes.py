"""The subtree factories (trees/prepare.py, trees/throw.py, trees/subtrees.py) build the
branches the README draws: built without a world, asked by node name."""

import py_trees
import pytest

from suture_bt.trees.prepare import prepare
from suture_bt.trees.subtrees import INSERTER, PULLER, in_reach
from suture_bt.trees.throw import picked_up_again, throw


@pytest.fixture(autouse=True)
def clean_blackboard():
    py_trees.blackboard.Blackboard.clear()
    yield
    py_trees.blackboard.Blackboard.clear()


def named(root, name: str):
    return next(n for n in root.iterate() if n.name == name)


def test_the_arms_roles_and_the_reach_check():
    assert (INSERTER, PULLER) == ("psm2", "psm1")
    assert in_reach((2,)).name == "All of pair 2 in reach?"
    assert in_reach((1, 2, 3, 4)).name == "All of pairs in reach?"


def test_the_preparation_lays_down_or_presents_and_starts_from_the_tissue_two_ways():
    root = prepare((1, 2, 3, 4))
    ways = [c.name for c in named(root, "Lay the needle down, else present it").children]
    assert ways == ["Prepare by laying the needle down", "Prepare from PSM2's jaw"]
    tissue = [c.name for c in named(root, "Prepare from the tissue").children]
    assert tissue == [
        "Calibrate both arms, then pick the needle up",
        "Else PSM2 picks it up first, then PSM1 calibrates",
    ]
    named(root, "Retry: prepare after a drop")  # the drop recovery wraps the jaw start


def test_a_drop_in_a_throw_is_taken_again_where_it_hangs_else_picked_up():
    choice = named(
        picked_up_again(3, (4,)), "Hanging in pair 3: take it again there, else pick it up"
    )
    assert [c.name for c in choice.children] == [
        "PSM1 takes it again in pair 3",
        "PSM2 takes it again part way through pair 3",
        "PSM2 picks the dropped needle up",
    ]
    part_way = [c.name for c in choice.children[1].children]
    assert part_way == [
        "Needle part way through pair 3?",
        "PSM2 takes the needle hanging in pair 3",
        "Drive the dropped needle on through pair 3",
        "Pull the re-driven needle through pair 3",
    ]


def test_a_throw_is_watched_retried_after_a_drop_and_hands_back_unless_last():
    middle, last = throw(2, (3, 4)), throw(4, ())
    for root, pair in ((middle, 2), (last, 4)):
        retry = named(root, f"Retry: pair {pair} after a drop")
        assert [c.name for c in retry.children] == [
            f"Pair {pair} (time limit)",
            f"Pick-up after a drop in pair {pair} (time limit)",
        ]
        named(root, f"Retry: insert pair {pair}")
        named(root, f"Retry: extract pair {pair}")
    named(middle, "Unless PSM2 already holds it")  # the hand-back
    assert not any(n.name == "Unless PSM2 already holds it" for n in last.iterate())
