"""The preparation subtree: both arms calibrated and the needle in PSM2's jaw at the grasp the
throws need.

SRC Task 3 starts with the needle in PSM2's jaw, and calibration needs an empty jaw. So the
preparation calibrates PSM1, and PSM2 lays the needle flat on the tissue where it can take it
again, calibrates with its jaw empty and picks the needle up at the grasp the throws need
(localising a needle resting on the tissue needs no presentation; one held in an uncalibrated
jaw does). When no spot can be used, PSM2 presents the needle instead: it is localised in its
jaw, handed to PSM1, PSM2 calibrates and takes it back. A needle starting on the tissue is
picked up after both arms calibrate (by PSM1 and handed over when PSM2 cannot take it), or,
when PSM1's calibration fails first, after PSM2's. A drop during the preparation is recovered
by finding the needle and picking it up (Nav2-style :class:`RecoveryNode`, one retry).
"""

from __future__ import annotations

import operator

import py_trees
from py_trees.common import ComparisonExpression

from suture_bt.behaviours import blackboard_keys as keys
from suture_bt.behaviours.actions import (
    Calibrate,
    FindDroppedNeedle,
    HandOver,
    LayDownNeedle,
    Localize,
    PickUpNeedle,
    away_from_holder_and,
    grasp_for_pairs,
)
from suture_bt.behaviours.conditions import (
    JawEmpty,
    JawHoldsSomething,
    NeedleDropped,
    NeedleStillHeld,
)
from suture_bt.behaviours.needle_start import NeedleStart
from suture_bt.behaviours.parallel import ParallelWithReason
from suture_bt.behaviours.recovery import recovery_idiom
from suture_bt.behaviours.sim_timeout import SimTimeout
from suture_bt.behaviours.throw_progress import (
    SkipWhen,
    calibrated,
    holds_needle,
    prepared,
)
from suture_bt.trees.subtrees import (
    INSERTER,
    PICK_UP_LIMIT,
    PREPARE_LIMIT,
    PULLER,
    RETRIES,
    calibrate_psm2_via_psm1,
    retried_handover,
)


def prepare(pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """Calibrate both arms and leave the needle in PSM2's jaw at the grasp ``pairs`` need."""
    grasp = grasp_for_pairs(pairs)
    laid_down = py_trees.composites.Sequence(
        "Prepare by laying the needle down",
        memory=True,
        children=[
            Calibrate(PULLER),
            LayDownNeedle(INSERTER, grasp),
            Calibrate(INSERTER, name="Calibrate PSM2 (jaw empty)"),
            picked_up_from_tissue(grasp, pairs[0], "PSM2 picks the laid down needle up"),
        ],
    )
    presented = py_trees.composites.Sequence(
        "Prepare from PSM2's jaw",
        memory=True,
        children=[
            JawHoldsSomething(INSERTER, name="Needle still in PSM2's jaw?"),
            SkipWhen("Unless PSM1 is calibrated", Calibrate(PULLER), calibrated(PULLER)),
            Localize(INSERTER),
            *calibrate_psm2_via_psm1(
                grasp,
                pairs[0],
                ("PSM2 hands the needle to PSM1", "Calibrate PSM2", "PSM1 hands it back"),
            ),
        ],
    )
    from_jaw = py_trees.composites.Selector(
        "Lay the needle down, else present it", memory=True, children=[laid_down, presented]
    )
    from_tissue = py_trees.composites.Selector(
        "Prepare from the tissue",
        memory=True,
        children=[
            py_trees.composites.Sequence(
                "Calibrate both arms, then pick the needle up",
                memory=True,
                children=[
                    Calibrate(PULLER),
                    Calibrate(INSERTER),
                    picked_up_from_tissue(grasp, pairs[0]),
                ],
            ),
            picked_up_before_psm1_calibrates(grasp),
        ],
    )
    choose = py_trees.idioms.either_or(
        conditions=[
            ComparisonExpression(keys.NEEDLE_START.name, "jaw", operator.eq),
            ComparisonExpression(keys.NEEDLE_START.name, "tissue", operator.eq),
        ],
        subtrees=[
            prepared_despite_a_drop(from_jaw, grasp),
            SimTimeout("Prepare from the tissue (time limit)", from_tissue, PREPARE_LIMIT),
        ],
        name="Where is the needle?",
    )
    return py_trees.composites.Sequence(
        "Prepare", memory=True, children=[NeedleStart(INSERTER), choose]
    )


def prepared_despite_a_drop(
    from_jaw: py_trees.behaviour.Behaviour, grasp
) -> py_trees.behaviour.Behaviour:
    """The preparation from PSM2's jaw with the needle watched: a drop (during the lay-down,
    a presentation, a handover, PSM2's calibration) is recovered by finding the needle where
    it fell; PSM2 is calibrated if it is not yet and picks it up at ``grasp``, and the
    retried preparation finds both arms ready and skips the rest."""
    watched = ParallelWithReason(
        "Prepare from PSM2's jaw, needle watched",
        policy=py_trees.common.ParallelPolicy.SuccessOnSelected([from_jaw], synchronise=False),
        children=[NeedleStillHeld(), from_jaw],
        voice=1,
    )
    pick_up = py_trees.composites.Sequence(
        "Pick up the needle dropped in preparation",
        memory=True,
        children=[
            NeedleDropped(),
            FindDroppedNeedle(INSERTER, grasp),
            SkipWhen(
                "Unless PSM2 is calibrated",
                Calibrate(INSERTER, name="Calibrate PSM2 (needle dropped)"),
                calibrated(INSERTER),
            ),
            PickUpNeedle(INSERTER, grasp, name="PSM2 picks the dropped needle up (preparation)"),
        ],
    )
    return recovery_idiom(
        "Retry: prepare after a drop",
        SkipWhen(
            "Unless both arms are ready",
            SimTimeout("Prepare (time limit)", watched, PREPARE_LIMIT),
            prepared(INSERTER, (PULLER, INSERTER)),
        ),
        SimTimeout("Pick-up after a drop in preparation (time limit)", pick_up, PICK_UP_LIMIT),
        RETRIES,
        blame_recovery=True,
    )


def picked_up_before_psm1_calibrates(grasp) -> py_trees.behaviour.Behaviour:
    """The resting start's second way, when the first failed (e.g. the needle lies where the
    cameras see it behind PSM1's jaw at its calibration pose, and the keypoints are lost in
    it): PSM2 calibrates and picks the needle up, which takes it out of that sight, then PSM1
    calibrates (what the first way finished is skipped)."""
    return py_trees.composites.Sequence(
        "Else PSM2 picks it up first, then PSM1 calibrates",
        memory=True,
        children=[
            JawEmpty(PULLER, name="PSM1's jaw empty?"),
            SkipWhen(
                "Unless PSM2 is calibrated",
                Calibrate(INSERTER, name="Calibrate PSM2 (first)"),
                calibrated(INSERTER),
            ),
            SkipWhen(
                "Unless PSM2 holds the needle",
                PickUpNeedle(INSERTER, grasp, name="PSM2 picks the needle up first"),
                holds_needle(INSERTER),
            ),
            SkipWhen(
                "Unless PSM1 is calibrated",
                Calibrate(PULLER, name="Calibrate PSM1 (needle held)"),
                calibrated(PULLER),
            ),
        ],
    )


def picked_up_from_tissue(
    grasp, first_pair: int, name: str | None = None
) -> py_trees.behaviour.Behaviour:
    """Localise the resting needle and pick it up with PSM2 at the throws' grasp (that
    pick-up called ``name``); when PSM2 cannot (out of its reach, refused, closed empty),
    PSM1 picks it up clear of that grasp (another angle if that one is out of its reach) and
    hands it to PSM2."""
    by_psm1 = py_trees.composites.Sequence(
        "PSM1 picks it up and hands it to PSM2",
        memory=True,
        children=[
            JawEmpty(INSERTER, name="PSM2's jaw empty?"),
            PickUpNeedle(PULLER, away_from_holder_and(grasp), free=True),
            retried_handover(
                HandOver(
                    PULLER,
                    INSERTER,
                    grasp,
                    next_pair=first_pair,
                    name="PSM1 hands the picked up needle to PSM2",
                )
            ),
        ],
    )
    return py_trees.composites.Selector(
        "Pick up with PSM2, else PSM1 and hand over",
        memory=True,
        children=[PickUpNeedle(INSERTER, grasp, name=name), by_psm1],
    )
