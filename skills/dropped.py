"""Skill: after a drop, let go, find the needle where it fell and judge whether it can be taken.

The watch beside a throw sees the drop in the holder's measured jaw (closed below the wire).
This skill is the first step of the recovery: the tree forgets the holder (the in-hand
transform is gone), the arm that dropped it opens its jaw and rises, both arms leave the
cameras' sight lines to where the needle most likely fell (straight below), the needle is given
a moment to come to rest, and it is localised from images where it lies. Then, from that
estimate alone, it says whether a pick-up can work: a needle caught in the tissue (hanging in
a port: part of its arc inside the phantom's known tissue solid near a port) that is not on
the throw's own circle (in the throw through a pair, a needle on that pair's circle is taken
again where it hangs: by the puller when its tip is out, else by the inserter), one on its edge
with no side grasp clear of the tissue, or one out of the picking arm's reach fails the skill
with a reason that starts "needle dropped by <arm> and ...", so the throw ends saying why. A
needle lying turned over, or standing on its edge, is taken as the pick-up takes it
(:mod:`~suture_bt.skills.resting_grasp`: the turned hand, or a side grasp); the throw that
resumes sees when that grasp cannot reach its pair and re-takes it through PSM1
(``grasp_reaches``).
Output: the free belief (holder None) the pick-up starts from.
"""

from __future__ import annotations

import numpy as np

from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import (
    NeedleBelief,
    NeedleNotSeen,
    NeedleObservation,
    TaskContext,
)
from suture_bt.skills.line_of_sight import clear_tip_pose
from suture_bt.skills.motion import feasible, jaw_to, move_to, together, wait
from suture_bt.skills.pick_up import look_for_resting
from suture_bt.skills.recover import JAW_OPEN
from suture_bt.skills.resting_grasp import grasp_path, resting_grasps
from suture_bt.skills.tip_reading import read_hanging
from suture_bt.transforms import invert

#: The fallen needle is given this long to come to rest before it is looked at (s); the arm
#: that dropped it rises this far from the tissue first (m).
SETTLE_S, RISE = 0.3, 0.010
#: A needle hanging in the tissue on the pair's planned circle (``checks.on_planned_circle``)
#: with its tip this far out past the exit (mm) is taken again by the extraction.
MIN_TIP_OUT_MM = 4.0
#: A seen needle with a point this far inside the phantom's known tissue solid (flat top and
#: ridge, :mod:`~suture_bt.geometry.tissue_surface`; vertical depth) is caught in the tissue:
#: hanging in a port when such a point lies within ``PORT_RADIUS`` of it (a ball: a port's
#: axis runs through the ridge and out over the flat tissue beyond it) (m).
UNDER_SURFACE, PORT_RADIUS = 0.001, 0.006


def dropped_by(context: TaskContext) -> tuple[str | None, str]:
    """The believed holder whose measured jaw closed below the wire (None: no drop), and why."""
    holder = context.holder()
    if holder is None:
        return None, "no arm is believed to hold the needle"
    angle = context.arm(holder).jaw_angle()
    held, detail = checks.jaw_holds_wire(angle)
    if angle <= checks.JAW_CLOSED_MAX and not held:
        return holder, f"needle dropped by {holder} ({detail})"
    return None, f"{holder} still holds the needle ({detail})"


def caught_in_tissue(context: TaskContext, T_world_needle: np.ndarray) -> str:
    """'' for a needle lying on the tissue (or on the ridge, arched over it); else where the
    seen arc goes into it."""
    pts = context.needle.centerline(60) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
    height = height_above_tissue(context.phantom, pts)
    inside = height < -UNDER_SURFACE
    if not inside.any():
        return ""
    depth = float(-height.min())
    for port in context.phantom.ports():
        near = np.linalg.norm(pts - port.position, axis=1) <= PORT_RADIUS
        if np.any(near & inside):
            return f"hanging in {port.name} ({1e3 * depth:.1f} mm under its surface)"
    T_ph = invert(context.phantom.T_world_phantom)
    z = pts @ T_ph[:3, :3].T + T_ph[:3, 3]
    if np.min(np.abs(z[:, 2] - TISSUE_TOP_Z)) < 0.005:  # part of it under the top, part above
        return f"stuck in the tissue ({1e3 * depth:.1f} mm under its surface)"
    return ""


def _on_circle(context: TaskContext, T_world_needle: np.ndarray, pair: int):
    """(why not, the sweep angle, the planned circle) of a needle pose on pair ``pair``'s
    circle (:func:`~suture_bt.skills.checks.on_planned_circle`; a pair with no circle: why)."""
    try:
        arc = context.plan(pair, f"pair {pair}")
    except SkillFailure as e:
        return e.reason, 0.0, None
    why_not, phi = checks.on_planned_circle(arc, T_world_needle, pair)
    return why_not, phi, arc


def _tip_out_mm(arc, phi: float) -> float:
    return 1e3 * arc.tip_height_above_exit(phi)


def hanging_in_pair(context: TaskContext, T_world_needle: np.ndarray, pair: int) -> str:
    """'' when the needle lies on pair ``pair``'s planned circle with its tip out past the
    exit far enough for the puller's grasp (dropped during the pull: the extraction can take
    it again where it hangs); else why not."""
    why_not, phi, arc = _on_circle(context, T_world_needle, pair)
    if why_not:
        return why_not
    out = _tip_out_mm(arc, phi)
    if out < MIN_TIP_OUT_MM:
        return f"its tip only {out:.1f} mm out past exit {pair} (< {MIN_TIP_OUT_MM:g} mm)"
    return ""


def _past_entry(context: TaskContext, T_world_needle: np.ndarray, pair: int):
    """:func:`_on_circle`, and why not when the tip is not yet past the entry."""
    why_not, phi, arc = _on_circle(context, T_world_needle, pair)
    if not why_not and phi <= 0.0:
        why_not = f"its tip not yet in entry {pair} (sweep {np.rad2deg(phi):.0f}°)"
    return why_not, phi, arc


def part_way_through(context: TaskContext, T_world_needle: np.ndarray, pair: int) -> str:
    """'' when the needle lies on pair ``pair``'s planned circle with its tip past the entry
    (in the tissue, or through it); else why not."""
    return _past_entry(context, T_world_needle, pair)[0]


def driven_in_pair(context: TaskContext, T_world_needle: np.ndarray, pair: int) -> str:
    """'' when the needle lies on pair ``pair``'s planned circle past the entry but short of
    the puller's grasp past the exit (dropped during the insertion: the inserting arm can take
    it again where it hangs and drive it on); else why not."""
    why_not, phi, arc = _past_entry(context, T_world_needle, pair)
    if why_not:
        return why_not
    if _tip_out_mm(arc, phi) >= MIN_TIP_OUT_MM:
        return f"its tip out past exit {pair} far enough for the puller"
    return ""


def pick_up_paths(context: TaskContext, T_world_needle: np.ndarray, arc_angle: float):
    """The pick-up's tip poses (hover, grasp, lift) for this resting needle, one path per way
    :class:`~suture_bt.skills.pick_up.PickUp` may take it (from above with the driving or the
    turned hand, or from the side on its edge), preferred first; SkillFailure (its reason) for
    a needle on its edge with no side grasp clear of the tissue."""
    return [
        grasp_path(context, T_world_needle, g.T_tip_needle)
        for g in resting_grasps(context, T_world_needle, arc_angle)
    ]


class FindDropped(Skill):
    """The needle fell from its holder: let go, localise it where it lies, and check that
    ``picker`` can take it at ``arc_angle`` (rad) (the other arms' reach is reported), or,
    in the throw through ``pair``, that it hangs on that pair's circle: with its tip out (the
    extraction takes it again), or part way through (the inserting arm takes it again and
    drives it on)."""

    name = "find dropped needle"

    def __init__(
        self, context: TaskContext, picker: str, arc_angle: float, pair: int | None = None
    ):
        super().__init__(context)
        self.picker, self.arc_angle, self.pair = picker, float(arc_angle), pair

    def program(self) -> Waiting:
        ctx = self.context
        arm, why = dropped_by(ctx)
        if arm is None:
            raise SkillFailure(f"no dropped needle to look for: {why}")
        self.report.update(dropped_by=arm, jaw=why)
        T_last = ctx.predicted_needle()
        # Dropped before any estimate (the start's holder): it fell from the holder's jaw.
        fell_from = ctx.arm(arm).tip_world()[:3, 3] if T_last is None else T_last[:3, 3]
        ctx.start_holder = None
        ctx.belief = None
        if T_last is not None:
            ctx.belief = NeedleBelief(T_last, ctx.clock.now(), "dropped", holder=None)
        self.say(f"{why}: {arm} opens its jaw and both arms make way for the cameras")
        yield from jaw_to(ctx.arm(arm), JAW_OPEN)
        yield from together(*self._make_way(arm, self._landing_guess(fell_from)))
        yield from wait(ctx.clock, SETTLE_S)
        self.say(f"looking for the needle dropped by {arm}")
        try:
            yield from self._look(T_last)
        except SkillFailure as e:
            raise SkillFailure(f"needle dropped by {arm} and not found: {e.reason}") from None
        T = ctx.belief.T_world_needle.copy()
        where = caught_in_tissue(ctx, T)
        if where and self.pair is not None:
            why_not = hanging_in_pair(ctx, T, self.pair)
            if not why_not:
                self.report.update(hanging_in_pair=self.pair, T_world_needle=T.tolist())
                self.say(f"needle dropped by {arm} {where}, on pair {self.pair}'s circle")
                return
            if not driven_in_pair(ctx, T, self.pair):
                self.report.update(driven_in_pair=self.pair, T_world_needle=T.tolist())
                self.say(f"needle dropped by {arm} {where}, part way along pair {self.pair}")
                return
            where = f"{where}, {why_not}"
        if where:
            raise SkillFailure(f"needle dropped by {arm} and {where}: it cannot be picked up")
        try:
            paths = pick_up_paths(ctx, T, self.arc_angle)
        except SkillFailure as e:
            raise SkillFailure(f"needle dropped by {arm} and {e.reason}") from None
        names = [self.picker] + [n for n in ctx.arms if n != self.picker]
        reach = {n: _reach(ctx.arm(n), paths) for n in names}
        self.report["reach"] = reach
        if reach[self.picker]:
            others = [n for n in names[1:] if not reach[n]]
            if not others:
                said = "; ".join(f"{n}: {r}" for n, r in reach.items())
                where = "both arms'" if len(names) == 2 else "every arm's"
                raise SkillFailure(f"needle dropped by {arm} and out of {where} reach: {said}")
            raise SkillFailure(
                f"needle dropped by {arm} and out of {self.picker}'s reach "
                f"({reach[self.picker]}); {', '.join(others)} could reach it, but only "
                f"{self.picker} picks it up in this tree"
            )
        at = np.round(1e3 * T[:3, 3], 1)
        self.report["T_world_needle"] = T.tolist()
        self.say(f"needle dropped by {arm} lies on the tissue at {at} mm, in {self.picker}'s reach")

    def _look(self, T_last: np.ndarray | None) -> Waiting:
        """Localise the fallen needle. Dropped while held at a known pose, it is first looked
        for there (:func:`seen_where_it_was`): the tissue holds a needle dropped part way
        through a pair where it was, partly hidden in the ridge, where an unprimed look may
        refuse it. A needle not seen there (it fell) is looked for anywhere (and once more
        after the arms make way, as the pick-up looks)."""
        if T_last is not None:
            if (yield from seen_where_it_was(self, T_last)):
                return
        yield from look_for_resting(self)

    def _landing_guess(self, p: np.ndarray) -> np.ndarray:
        """Where a needle falling from ``p`` (world) lands first: straight down on the tissue
        top."""
        T_ph = self.context.phantom.T_world_phantom
        up, top = T_ph[:3, 2], (T_ph @ np.array([0.0, 0.0, TISSUE_TOP_Z, 1.0]))[:3]
        return p - float((p - top) @ up) * up

    def _make_way(self, dropper: str, target: np.ndarray) -> list[Waiting]:
        """The dropper rises ``RISE`` from the tissue; every arm leaves the sight lines from
        the cameras to ``target`` (backing off along the jaws would put the shaft in them)."""
        ctx = self.context
        up = ctx.phantom.T_world_phantom[:3, 2]
        moves = []
        for name, a in ctx.arms.items():
            T = a.commanded_tip_world()
            if name == dropper:
                T[:3, 3] += RISE * up
            cleared = clear_tip_pose(ctx, T, a.base_frame()[:3, 3], target)
            T = T if cleared is None else cleared
            if (name == dropper or cleared is not None) and not feasible(a, [T]):
                moves.append(move_to(ctx.clock, a, [T], "make way for the cameras"))
        return moves


def _reach(arm, paths: list[list[np.ndarray]]) -> str:
    """'' when ``arm`` can follow one of ``paths``; else why not (the preferred path's)."""
    whys = [feasible(arm, path) for path in paths]
    return "" if not all(whys) else whys[0]


def seen_where_it_was(skill: Skill, T_last: np.ndarray) -> Waiting:
    """True when a free needle is seen where it was last believed (``T_last``, world), and
    adopted as the belief: a look checked against that pose, else that frame read along the
    circle it was on (:func:`~suture_bt.skills.tip_reading.read_hanging`) when the reading
    lies in the tissue. ``skill.report["where_it_was"]`` says which, or why not."""
    ctx = skill.context
    yield
    try:
        obs = ctx.sensor.observe(T_last, prior_checked=True)
        ok, detail = checks.poses_agree(obs.T_world_needle, T_last)
    except NeedleNotSeen as e:
        ok, detail = False, e.reason
    skill.report["where_it_was"] = detail if ok else f"not there: {detail}"
    if ok:
        ctx.believe(obs, None)
        return True
    reading = read_hanging(ctx.sensor, ctx.needle, ctx.phantom, T_last)
    if reading is None or not caught_in_tissue(ctx, reading.T_world_needle):
        return False
    skill.report["where_it_was"] = (
        f"hanging there: read {reading.turn_deg:+.0f}° along the circle it was held on "
        f"({100 * reading.on:.0f} % of the open circle explained)"
    )
    stamp = ctx.sensor.last_frame.stamp
    ctx.believe(NeedleObservation(reading.T_world_needle, stamp, 0.0, 0.0, "image-read"), None)
    return True
