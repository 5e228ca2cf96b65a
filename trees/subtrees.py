"""Subtrees shared by the suture trees: preparing both arms, and one throw.

SRC Task 3 starts with the needle in PSM2's jaw, and calibration needs an empty jaw. So the
preparation calibrates PSM1, localises the needle (presented by PSM2), hands it to PSM1,
calibrates PSM2 and takes it back at the grasp the throws need (its in-hand transform then
re-estimated from images with a calibrated arm). A throw: PSM2 inserts through the entry,
PSM1 pulls it through the exit, and (unless it is the last) hands it back to PSM2.
"""

from __future__ import annotations

import operator

import py_trees
from py_trees.common import ComparisonExpression

from suture_bt.behaviours import blackboard_keys as keys
from suture_bt.behaviours.actions import (
    Calibrate,
    ExtractNeedle,
    HandOver,
    InsertNeedle,
    Localize,
    PickUpNeedle,
    StandByAtExit,
    away_from_holder_and,
    grasp_for_pairs,
)
from suture_bt.behaviours.conditions import NeedleLocalised, PairsInReach
from suture_bt.behaviours.needle_start import NeedleStart
from suture_bt.behaviours.sim_timeout import SimTimeout
from suture_bt.behaviours.throw_scope import ThrowScope

#: Inserting arm (reaches the entries) and pulling arm (reaches the exits) of the SRC scene.
INSERTER, PULLER = "psm2", "psm1"
#: Simulated-time limits (s): preparation, and one throw.
PREPARE_LIMIT, THROW_LIMIT = 60.0, 45.0


def prepare(pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """Calibrate both arms and leave the needle in PSM2's jaw at the grasp ``pairs`` need."""
    grasp = grasp_for_pairs(pairs)
    from_jaw = py_trees.composites.Sequence(
        "Prepare from PSM2's jaw",
        memory=True,
        children=[
            Calibrate(PULLER),
            Localize(INSERTER),
            HandOver(
                INSERTER,
                PULLER,
                away_from_holder_and(grasp),
                pulling=True,
                name="PSM2 hands the needle to PSM1",
            ),
            Calibrate(INSERTER),
            HandOver(
                PULLER, INSERTER, grasp, next_pair=pairs[0], name="PSM1 hands it back"
            ),
        ],
    )
    from_tissue = py_trees.composites.Sequence(
        "Prepare from the tissue",
        memory=True,
        children=[Calibrate(PULLER), Calibrate(INSERTER), *pick_up_children(grasp)],
    )
    choose = py_trees.idioms.either_or(
        conditions=[
            ComparisonExpression(keys.NEEDLE_START.name, "jaw", operator.eq),
            ComparisonExpression(keys.NEEDLE_START.name, "tissue", operator.eq),
        ],
        subtrees=[from_jaw, from_tissue],
        name="Where is the needle?",
    )
    seq = py_trees.composites.Sequence(
        "Prepare", memory=True, children=[NeedleStart(INSERTER), choose]
    )
    return SimTimeout("Prepare (time limit)", seq, PREPARE_LIMIT)


def in_reach(pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """Both arms can reach the planned poses of the throws through ``pairs``."""
    label = f"pair {pairs[0]}" if len(pairs) == 1 else "pairs"
    return PairsInReach(pairs, INSERTER, PULLER, name=f"All of {label} in reach?")


def pick_up_children(grasp) -> list[py_trees.behaviour.Behaviour]:
    """Localise the resting needle and pick it up with PSM2 at the throws' grasp."""
    return [PickUpNeedle(INSERTER, grasp)]


def insert_while_standing_by(pair: int) -> py_trees.behaviour.Behaviour:
    """PSM2 inserts while PSM1 comes to wait at the exit (optional: a PSM1 that cannot wait
    there comes from where it is; the extraction checks its own reach)."""
    return py_trees.composites.Parallel(
        f"Insert pair {pair}, PSM1 waits",
        policy=py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True),
        children=[
            InsertNeedle(INSERTER, pair),
            py_trees.decorators.FailureIsSuccess(
                "Waiting is optional", StandByAtExit(PULLER, pair)
            ),
        ],
    )


def throw(pair: int, later_pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """One throw through ``pair``; ``later_pairs`` decide the grasp PSM2 takes back."""
    steps = [
        in_reach((pair,)),
        NeedleLocalised(INSERTER, name="Needle in PSM2's hand?"),
        insert_while_standing_by(pair),
        ExtractNeedle(PULLER, INSERTER, pair),
    ]
    if later_pairs:
        steps.append(
            HandOver(
                PULLER,
                INSERTER,
                grasp_for_pairs(later_pairs),
                next_pair=later_pairs[0],
                name=f"Hand back after pair {pair}",
            )
        )
    seq = py_trees.composites.Sequence(f"Pair {pair} steps", memory=True, children=steps)
    return ThrowScope(pair, SimTimeout(f"Pair {pair} (time limit)", seq, THROW_LIMIT))
