"""One throw's subtree: PSM2 inserts through the entry, PSM1 pulls it through the exit, and
(unless it is the last) hands it back to PSM2.

Before each insertion the needle is looked at over the entry: a slip (the needle seen away from
its predicted pose, its wire still between the blades) re-estimates the in-hand pose and, when
the grasp then leaves the tip too little room, PSM2 re-grasps through PSM1; a drift (the wire
seen off the calibrated pinch point) recalibrates PSM2 with an empty jaw (PSM1 holds the
needle meanwhile).

Recovery branches (Nav2-style :class:`RecoveryNode`, one retry each): a failed handover is
retried after the taker re-opens and backs off and the giver's needle is re-localised; an
extraction whose grasp closed empty re-opens, backs off and tries again; an insertion not
confirmed is looked at again (a needle at the end of its sweep is then only confirmed), or
backed out along its arc, re-localised and inserted once more. A watch beside every throw's
steps fails the attempt when the holder's jaw closes below the wire ("needle dropped by
psm2"); the needle is then found where it fell and picked up by PSM2 at the grasp the pairs
still to do need (from the side when it stands on its edge), or, held by the tissue on the
pair's circle, taken again where it hangs (tip out: PSM1 pulls it through; part way: PSM2
drives it on and PSM1 pulls it through), and the throw's steps run again without redoing
what is done. A needle that cannot be taken fails the throw saying why.
"""

from __future__ import annotations

import py_trees

from suture_bt.behaviours.actions import (
    BackOutNeedle,
    CheckNeedleInHand,
    ExtractNeedle,
    FindDroppedNeedle,
    HandOver,
    InsertNeedle,
    LetGoOfNeedleInTissue,
    Localize,
    OpenAndBackOffArm,
    PickUpNeedle,
    StandByAtExit,
    TakeHangingNeedle,
    away_from_holder_and,
    furthest_back,
    grasp_for_pairs,
)
from suture_bt.behaviours.conditions import (
    CalibrationLost,
    GraspMissed,
    NeedleDrivenInPair,
    NeedleDropped,
    NeedleHangingInPair,
    NeedleLocalised,
    NeedleStillHeld,
    TipSeenShort,
)
from suture_bt.behaviours.parallel import ParallelWithReason
from suture_bt.behaviours.recovery import recovery_idiom
from suture_bt.behaviours.sim_timeout import SimTimeout
from suture_bt.behaviours.throw_progress import (
    SkipWhen,
    grasp_for_remaining,
    grasp_leaves_room,
    grasp_reaches,
    holds_needle,
    pulled_through,
)
from suture_bt.behaviours.throw_scope import ThrowScope
from suture_bt.trees.subtrees import (
    INSERTER,
    PICK_UP_LIMIT,
    PULLER,
    RETRIES,
    THROW_LIMIT,
    calibrate_psm2_via_psm1,
    in_reach,
    retried_handover,
)


def insert_while_standing_by(pair: int) -> py_trees.behaviour.Behaviour:
    """PSM2 inserts while PSM1 comes to wait at the exit (optional: a PSM1 that cannot wait
    there comes from where it is; the extraction checks its own reach)."""
    return ParallelWithReason(
        f"Insert pair {pair}, PSM1 waits",
        policy=py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True),
        children=[
            InsertNeedle(INSERTER, pair),
            py_trees.decorators.FailureIsSuccess(
                "Waiting is optional", StandByAtExit(PULLER, pair)
            ),
        ],
    )


def retried_insertion(pair: int) -> py_trees.behaviour.Behaviour:
    """Insert; when the emerged tip is not confirmed, first look at it again (the frames may
    have been lost or dark: then the retry only confirms); a tip seen out but short with the
    grasp at its limit is let go (the tissue holds it), taken again further back and driven
    on; else back out along the arc (never a tip seen out past the exit), re-localise the
    needle in PSM2's hand (a fresh in-hand transform) and insert once more."""
    further_back = py_trees.composites.Sequence(
        f"Take it further back and drive on (pair {pair})",
        memory=True,
        children=[
            TipSeenShort(pair),
            LetGoOfNeedleInTissue(INSERTER, pair),
            TakeHangingNeedle(
                INSERTER, pair, furthest_back, name=f"PSM2 takes it further back (pair {pair})"
            ),
            InsertNeedle(INSERTER, pair, f"Drive on from further back through pair {pair}"),
        ],
    )
    back_out = py_trees.composites.Sequence(
        f"Back out of pair {pair} and re-localise",
        memory=True,
        children=[
            NeedleLocalised(INSERTER, name="Needle still in PSM2's hand?"),
            BackOutNeedle(INSERTER, pair),
            Localize(INSERTER),
        ],
    )
    recovery = py_trees.composites.Selector(
        f"Recover insertion {pair}",
        memory=True,
        children=[
            InsertNeedle(INSERTER, pair, f"Look at the tip past exit {pair} again", True),
            further_back,
            back_out,
        ],
    )
    return recovery_idiom(
        f"Retry: insert pair {pair}", insert_while_standing_by(pair), recovery, RETRIES
    )


def retried_extraction(pair: int) -> py_trees.behaviour.Behaviour:
    """Extract; when PSM1's jaw closed empty, it re-opens, backs off and tries again."""
    recovery = py_trees.composites.Sequence(
        f"PSM1 re-opens after a miss at pair {pair}",
        memory=True,
        children=[GraspMissed(PULLER), OpenAndBackOffArm(PULLER)],
    )
    return recovery_idiom(
        f"Retry: extract pair {pair}", ExtractNeedle(PULLER, INSERTER, pair), recovery, RETRIES
    )


def checked_in_hand(pair: int, later_pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """The in-hand check before inserting; when it finds PSM2's calibration lost (drift), PSM2
    hands the needle to PSM1, is calibrated again (empty jaw) and takes it back, and the
    needle is checked again."""
    grasp = grasp_for_pairs((pair, *later_pairs))
    recalibrate = py_trees.composites.Sequence(
        f"Recalibrate PSM2 (pair {pair})",
        memory=True,
        children=[
            CalibrationLost(INSERTER),
            *calibrate_psm2_via_psm1(
                grasp,
                pair,
                (
                    f"PSM2 hands the needle to PSM1 to recalibrate (pair {pair})",
                    f"Recalibrate PSM2 (pair {pair}, empty jaw)",
                    f"PSM1 hands it back recalibrated (pair {pair})",
                ),
            ),
        ],
    )
    return recovery_idiom(
        f"Retry: check pair {pair} after recalibrating",
        CheckNeedleInHand(INSERTER, pair),
        recalibrate,
        RETRIES,
        blame_recovery=True,
    )


def regrasp(
    pair: int, later_pairs: tuple[int, ...], why: str = "slipped"
) -> py_trees.behaviour.Behaviour:
    """PSM2's grasp (after a slip) leaves the tip too little room, or (``why`` "to re-take
    it") cannot reach the pair's approach: PSM1 takes the needle and hands it back at the
    grasp the pairs from ``pair`` on need."""
    grasp = grasp_for_pairs((pair, *later_pairs))
    tag = "" if why == "slipped" else f" {why}"
    give = (
        f"PSM2 hands the slipped needle to PSM1 (pair {pair})"
        if why == "slipped"
        else f"PSM2 hands the needle to PSM1 {why} (pair {pair})"
    )
    return py_trees.composites.Sequence(
        f"Re-grasp for pair {pair}{tag}: PSM2 → PSM1 → PSM2",
        memory=True,
        children=[
            retried_handover(
                HandOver(
                    INSERTER,
                    PULLER,
                    away_from_holder_and(grasp),
                    pulling=True,
                    name=give,
                )
            ),
            retried_handover(
                HandOver(
                    PULLER,
                    INSERTER,
                    grasp,
                    next_pair=pair,
                    name=f"PSM1 hands it back for pair {pair}{tag}",
                )
            ),
        ],
    )


def picked_up_again(pair: int, later_pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """After a drop: let go, find the needle where it fell, and PSM2 picks it up at the grasp
    the pairs still to do need; or, hanging on this pair's circle, it is taken again where it
    hangs: with its tip out (dropped while pulled) PSM1 pulls it through; part way (dropped
    while inserted) PSM2 drives it on and PSM1 pulls it through. Fails saying why when none
    can: elsewhere in the tissue, on its edge with no side grasp, out of reach, not found."""
    grasp = grasp_for_remaining(pair, later_pairs)
    re_take = py_trees.composites.Sequence(
        f"PSM1 takes it again in pair {pair}",
        memory=True,
        children=[
            NeedleHangingInPair(pair),
            ExtractNeedle(
                PULLER, INSERTER, pair, name=f"Pull the dropped needle through pair {pair}"
            ),
        ],
    )
    drive_on = py_trees.composites.Sequence(
        f"PSM2 takes it again part way through pair {pair}",
        memory=True,
        children=[
            NeedleDrivenInPair(pair),
            TakeHangingNeedle(INSERTER, pair, grasp),
            InsertNeedle(INSERTER, pair, f"Drive the dropped needle on through pair {pair}"),
            ExtractNeedle(
                PULLER, INSERTER, pair, name=f"Pull the re-driven needle through pair {pair}"
            ),
        ],
    )
    return py_trees.composites.Sequence(
        f"Pick up the needle dropped in pair {pair}",
        memory=True,
        children=[
            NeedleDropped(),
            FindDroppedNeedle(INSERTER, grasp, pair),
            py_trees.composites.Selector(
                f"Hanging in pair {pair}: take it again there, else pick it up",
                memory=True,
                children=[
                    re_take,
                    drive_on,
                    PickUpNeedle(INSERTER, grasp, name="PSM2 picks the dropped needle up"),
                ],
            ),
        ],
    )


def throw(pair: int, later_pairs: tuple[int, ...]) -> py_trees.behaviour.Behaviour:
    """One throw through ``pair``; ``later_pairs`` decide the grasp PSM2 takes back. A drop
    (the watch) is recovered by a pick-up and the throw's steps run again, skipping what is
    done: a pair pulled through is not inserted again, a needle picked up by PSM2 at the
    later pairs' grasp needs no hand-back."""
    work = py_trees.composites.Sequence(
        f"Insert and extract pair {pair}",
        memory=True,
        children=[
            NeedleLocalised(INSERTER, name="Needle in PSM2's hand?"),
            SkipWhen(
                f"Unless the grasp reaches pair {pair}",
                regrasp(pair, later_pairs, "to re-take it"),
                grasp_reaches(pair, INSERTER),
            ),
            checked_in_hand(pair, later_pairs),
            SkipWhen(
                f"Unless the grasp leaves the tip room (pair {pair})",
                regrasp(pair, later_pairs),
                grasp_leaves_room(pair, INSERTER),
            ),
            retried_insertion(pair),
            retried_extraction(pair),
        ],
    )
    steps = [
        in_reach((pair,)),
        SkipWhen(f"Unless pair {pair} is pulled through", work, lambda c: pulled_through(c, pair)),
    ]
    if later_pairs:
        hand_back = retried_handover(
            HandOver(
                PULLER,
                INSERTER,
                grasp_for_pairs(later_pairs),
                next_pair=later_pairs[0],
                name=f"Hand back after pair {pair}",
            )
        )
        steps.append(SkipWhen("Unless PSM2 already holds it", hand_back, holds_needle(INSERTER)))
    seq = py_trees.composites.Sequence(f"Pair {pair} steps", memory=True, children=steps)
    watched = ParallelWithReason(
        f"Pair {pair}, needle watched",
        policy=py_trees.common.ParallelPolicy.SuccessOnSelected([seq], synchronise=False),
        children=[NeedleStillHeld(), seq],
        voice=1,
    )
    retried = recovery_idiom(
        f"Retry: pair {pair} after a drop",
        SimTimeout(f"Pair {pair} (time limit)", watched, THROW_LIMIT),
        SimTimeout(
            f"Pick-up after a drop in pair {pair} (time limit)",
            picked_up_again(pair, later_pairs),
            PICK_UP_LIMIT,
        ),
        RETRIES,
        blame_recovery=True,
    )
    return ThrowScope(pair, retried)
