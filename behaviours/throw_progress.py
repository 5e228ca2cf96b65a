"""What a throw has already done, so that a throw retried after a recovery does not redo it.

A throw retried after its needle was dropped starts its steps again. Work already done and
scored must not be repeated: a pair whose needle was pulled through (an extraction of this
pair succeeded in this throw) is not inserted again, and a needle picked up by the inserting
arm at the later pairs' grasp needs no hand-back. :class:`SkipWhen` skips a step when its
question says it is done (SUCCESS, "skipped: ..."), from the tree's own records only.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import py_trees
from py_trees.behaviour import Behaviour
from py_trees.common import Status

from suture_bt.behaviours.actions import AngleRule, grasp_for_pairs
from suture_bt.behaviours.skill_behaviour import needs
from suture_bt.planning import NeedleArcError, plan_needle_arc
from suture_bt.skills.context import TaskContext
from suture_bt.skills.grasps import JAW_CLEARANCE
from suture_bt.skills.insert import LIFT, PRE_ARC
from suture_bt.skills.motion import feasible
from suture_bt.transforms import invert

#: Says why a step is already done ('' when it is not).
DoneCheck = Callable[[TaskContext], str]


class SkipWhen(py_trees.decorators.Decorator):
    """Run ``child`` unless ``done(context)`` says its work is done: then SUCCESS at once,
    without ticking it, and ``feedback_message`` says "skipped: <why>"."""

    def __init__(self, name: str, child: Behaviour, done: DoneCheck):
        super().__init__(name=name, child=child)
        self.done = done
        self.context: TaskContext | None = None
        self.skipped = False

    def setup(self, **kwargs) -> None:
        self.context = needs(kwargs, "context", f"decorator {self.name!r}")

    def tick(self) -> Iterator[Behaviour]:
        """Ask once per run (when not RUNNING); skip, or tick the child as a Decorator does."""
        if self.status != Status.RUNNING:
            why = self.done(self.context)
            self.skipped = bool(why)
            if why:
                if self.decorated.status != Status.INVALID:
                    self.decorated.stop(Status.INVALID)
                self.feedback_message = f"skipped: {why}"
                self.stop(Status.SUCCESS)
                yield self
                return
        yield from super().tick()

    def update(self) -> Status:
        self.feedback_message = self.decorated.feedback_message
        return self.decorated.status


def pulled_through(ctx: TaskContext, pair: int) -> str:
    """'' unless an extraction succeeded since throw ``pair`` started (its own reports)."""
    rec = ctx.throws.get(pair)
    if rec is None:
        return ""
    for r in reversed(ctx.reports):
        if r.get("t_start", -1.0) < rec["t_start"]:
            break
        if r.get("skill") == "extract" and r.get("status") == "SUCCESS":
            return f"pair {pair} pulled through at t = {r['t_end']:.1f} s"
    return ""


def holds_needle(arm: str) -> DoneCheck:
    """'' unless ``arm`` is believed to hold the needle with a known in-hand pose."""

    def check(ctx: TaskContext) -> str:
        b = ctx.belief
        if b is None or b.holder != arm or b.T_tip_needle is None:
            return ""
        return f"{arm} already holds the needle (source {b.source})"

    return check


def prepared(holder: str, arms: tuple[str, ...]) -> DoneCheck:
    """'' unless every one of ``arms`` is calibrated and ``holder`` holds the needle with a
    known in-hand pose (what the preparation leaves: a preparation that picked up a needle
    dropped on its way there has nothing left to do)."""
    held = holds_needle(holder)

    def check(ctx: TaskContext) -> str:
        says = held(ctx)
        if not says or not all(ctx.arm(a).calibrated for a in arms):
            return ""
        return f"{', '.join(arms)} calibrated and {says}"

    return check


def calibrated(arm: str) -> DoneCheck:
    """'' unless ``arm`` is calibrated (its calibration not found lost since)."""

    def check(ctx: TaskContext) -> str:
        return f"{arm} is calibrated" if ctx.arm(arm).calibrated else ""

    return check


def _held_and_planned(ctx: TaskContext, pair: int, arm: str):
    """(the belief, the planned circle through ``pair``) when ``arm`` is known to hold the
    needle and the pair has a circle; else (why the grasp is left to the insertion, None)."""
    b = ctx.belief
    if b is None or b.holder != arm or b.T_tip_needle is None:
        return f"{arm} is not known to hold the needle (the insertion says so)", None
    try:
        return b, plan_needle_arc(*ctx.phantom.pair(pair), ctx.needle)
    except NeedleArcError as e:
        return f"no circle through pair {pair} ({e.reason}; the insertion says so)", None


def grasp_reaches(pair: int, arm: str) -> DoneCheck:
    """'' when ``arm`` cannot bring the needle, as its believed grasp holds it, to the
    approach poses of ``pair`` (a grasp taken off the tissue can leave the wrist no way to
    them, though the pair is in reach with the task's grasp: a re-grasp is needed);
    anything else is left to the in-hand check and the insertion to judge."""

    def check(ctx: TaskContext) -> str:
        b, arc = _held_and_planned(ctx, pair, arm)
        if arc is None:
            return b
        T_inv = invert(b.T_tip_needle)
        poses = [T @ T_inv for T in arc.approach_poses(PRE_ARC, LIFT)]
        if feasible(ctx.arm(arm), poses):
            return ""
        return f"{arm}'s grasp reaches pair {pair}'s approach"

    return check


def grasp_leaves_room(pair: int, arm: str) -> DoneCheck:
    """'' when ``arm``'s believed grasp fails the planner's grasp limit for ``pair`` (too close
    to the tip: a re-grasp is needed); anything else is left to the insertion to judge."""

    def check(ctx: TaskContext) -> str:
        b, arc = _held_and_planned(ctx, pair, arm)
        if arc is None:
            return b
        try:
            arc.check_grasp(b.T_tip_needle, JAW_CLEARANCE)
        except NeedleArcError:
            return ""
        return f"{arm}'s grasp leaves the tip room for pair {pair}"

    return check


def grasp_for_remaining(pair: int, later: tuple[int, ...]) -> AngleRule:
    """The grasp the pairs still to do need: from ``pair`` on, or only the later ones once
    ``pair`` was pulled through (a needle dropped during the hand-back)."""
    from_here, after = grasp_for_pairs((pair, *later)), grasp_for_pairs(later)

    def rule(ctx: TaskContext) -> float:
        return after(ctx) if later and pulled_through(ctx, pair) else from_here(ctx)

    return rule
