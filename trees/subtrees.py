"""What the suture trees' subtrees share: the two arms' roles, time limits, retries, and the
small pieces both the preparation (:mod:`~suture_bt.trees.prepare`) and the throws
(:mod:`~suture_bt.trees.throw`) use: a pair-reach check, a handover retried after the taker
backs off and the giver's needle is re-localised, and PSM2's calibration with its jaw emptied
through PSM1 (calibration needs an empty jaw).
"""

from __future__ import annotations

import py_trees

from suture_bt.behaviours.actions import (
    Calibrate,
    HandOver,
    Localize,
    OpenAndBackOffArm,
    away_from_holder_and,
)
from suture_bt.behaviours.conditions import (
    NeedleLocalised,
    PairsInReach,
)
from suture_bt.behaviours.recovery import recovery_idiom

#: Inserting arm (reaches the entries) and pulling arm (reaches the exits) of the SRC scene.
INSERTER, PULLER = "psm2", "psm1"
#: Simulated-time limits (s): preparation, one attempt of a throw, a pick-up after a drop.
PREPARE_LIMIT, THROW_LIMIT, PICK_UP_LIMIT = 60.0, 45.0, 40.0
#: Retries of each recovery branch.
RETRIES = 1


def in_reach(pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """Both arms can reach the planned poses of the throws through ``pairs``."""
    label = f"pair {pairs[0]}" if len(pairs) == 1 else "pairs"
    return PairsInReach(pairs, INSERTER, PULLER, name=f"All of {label} in reach?")


def retried_handover(handover: HandOver) -> py_trees.behaviour.Behaviour:
    """The handover; when it fails with the needle still in the giver's jaw, the taker
    re-opens and backs off, the giver's needle is localised again, and it is tried again."""
    giver, taker = handover.giver, handover.taker
    recovery = py_trees.composites.Sequence(
        f"Re-localise in {giver.upper()}, {taker.upper()} backs off",
        memory=True,
        children=[
            NeedleLocalised(giver, name=f"Needle still in {giver.upper()}'s hand?"),
            OpenAndBackOffArm(taker),
            Localize(giver),
        ],
    )
    return recovery_idiom(f"Retry: {handover.name}", handover, recovery, RETRIES)


def calibrate_psm2_via_psm1(
    grasp, next_pair: int, names: tuple[str, str, str]
) -> list[py_trees.behaviour.Behaviour]:
    """PSM2 hands the needle to PSM1, is calibrated with its jaw empty, and takes it back at
    ``grasp`` (calibration needs an empty jaw); ``names``: the three steps' names."""
    give, calibrate, back = names
    return [
        retried_handover(
            HandOver(INSERTER, PULLER, away_from_holder_and(grasp), pulling=True, name=give)
        ),
        Calibrate(INSERTER, name=calibrate),
        retried_handover(HandOver(PULLER, INSERTER, grasp, next_pair=next_pair, name=back)),
    ]
