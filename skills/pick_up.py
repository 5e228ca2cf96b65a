"""Skill: pick up a needle lying free (resting on the tissue) at a chosen arc angle.

The needle is localised where it lies; the jaws come down on it from above, across the needle
plane with the wire along tip x (the driving hand of :mod:`grasps`, ``GRASP_DEPTH`` behind the
tip), from a hover pose ``APPROACH`` back along their length; they close, and the jaw's measured
angle must show the wire between the blades (an empty close backs off before failing); the arm
lifts the needle along the phantom's up axis; the estimate is re-anchored to the gripper, the
needle is presented to the cameras and a fresh estimate must agree with where the gripper put
it (the needle moved with it) and be held near the asked arc angle. Output: the belief with the
arm as holder and the in-hand transform re-estimated from images.

A resting needle lies roughly flat: its z axis points up (the SRC rest pose: identity rotation)
or down (turned over). The driving hand puts tip z = −needle z, so on a needle turned over it
would come from below the tissue: the skill then takes it with the only hand the geometry
allows, the same grasp turned half a turn about the wire (tip z = +needle z, jaws from above),
and says so in its feedback and report (``hand``: "driving" or "turned over"). That grasp is
not the one the insertion planner drives with: before a throw the tree sees that the wrist
cannot bring it to the entry (``grasp_reaches``) and re-grasps it through PSM1 (PSM2 → PSM1 →
PSM2), which gave the driving hand back on both report runs whose laid-down needle flipped
(an earlier check at 40-120° arc angles had found no handover that does; not re-checked).
A needle on its edge (no jaw direction within ``MAX_TILT`` of straight down: one dropped on
its way to an entry comes to rest arched over the ridge) is taken from the side, at the arc
angle nearest the asked one that stands clear of the tissue (:mod:`resting_grasp`); the held
angle is then checked against that one.
"""

from __future__ import annotations

import numpy as np

from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.skills import checks
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import ArmHandle, NeedleNotSeen, NeedleObservation, TaskContext
from suture_bt.skills.grasps import END_MARGIN, backed_off, held_arc_angle
from suture_bt.skills.line_of_sight import (
    hidden_behind,
    make_way,
    make_way_for,
    ray_meets_plane,
)
from suture_bt.skills.localize_needle import LocalizeNeedle
from suture_bt.skills.motion import FINE, feasible, jaw_to, move_to, together
from suture_bt.skills.resting_grasp import (
    APPROACH,
    BLADE_BEYOND_TIP,
    LIFT,
    RestingGrasp,
    grasp_path,
    lies_on_tissue,
    resting_grasps,
    resting_tilt,
)
from suture_bt.transforms import invert

#: Jaw opening for the approach (rad).
JAW_OPEN = 0.8
#: The grasp the images confirm must be this close to the asked arc angle (rad).
ARC_TOLERANCE = np.deg2rad(10.0)
#: Arc-angle steps (rad) a free pick-up tries from the asked angle, nearest first.
FREE_STEPS = tuple(np.deg2rad(d) for d in (0.0, 15.0, -15.0, 30.0, -30.0))


class PickUp(Skill):
    """``arm`` (None: whichever can reach, calibrated first) picks up the free needle and
    holds it at ``arc_angle`` (rad)."""

    name = "pick up"

    def __init__(self, context: TaskContext, arm: str | None, arc_angle: float, free: bool = False):
        super().__init__(context)
        self.arm_name = arm
        self.arc_angle = float(arc_angle)
        #: Any arc angle will do (the taker hands it on): others are tried when this one's
        #: grasp is out of reach (``FREE_STEPS`` away either side).
        self.free = free

    def program(self) -> Waiting:
        ctx = self.context
        belief = ctx.belief
        if belief is not None and belief.holder is not None:
            raise SkillFailure(f"pick up: the needle is held by {belief.holder}")
        asked = np.rad2deg(self.arc_angle)
        self.report["arc_angle_deg"] = float(asked)
        if ctx.needle_hint is not None:  # laid down there: no arm in the cameras' way
            self.say("the arms make way for the cameras")
            yield from together(*make_way(ctx, np.asarray(ctx.needle_hint, dtype=float)))
        self.say("looking for the needle")
        yield from look_for_resting(self)
        ctx.needle_hint = None
        T_needle = ctx.belief.T_world_needle.copy()

        arm, grasp, goal = self._reach_some_angle(T_needle)
        which = grasp.hand
        if abs(grasp.arc_angle - self.arc_angle) > 1e-9:  # the clear point, or a free angle
            asked = float(np.rad2deg(grasp.arc_angle))
            self.report["taken_at_arc_angle_deg"] = asked
        hover = backed_off(goal, APPROACH)
        self.report.update(
            arm=arm.name,
            hand=which,
            T_world_tip_goal=goal.tolist(),
            blade_end_below_tissue_mm=self._blade_depth_mm(goal),
        )
        if not arm.calibrated:
            self.report["uncalibrated"] = True

        self.say(f"{arm.name} comes over the needle at {asked:.0f}° ({which} hand)")
        arm.arm.jaw.move_jp(np.array([JAW_OPEN]))  # opens on the way
        yield from move_to(ctx.clock, arm, [hover], "hover over the needle")
        yield from jaw_to(arm, JAW_OPEN)
        self.say(f"{arm.name} comes down on the needle")
        yield from move_to(ctx.clock, arm, [goal], "reach the grasp", FINE, joint_ok=False)
        yield from jaw_to(arm, 0.0)
        held, detail = checks.jaw_holds_wire(arm.jaw_angle())
        if not held:  # leave the tissue before failing: open and go back up
            yield from jaw_to(arm, JAW_OPEN)
            yield from move_to(ctx.clock, arm, [hover], "back off", FINE, joint_ok=False)
        self.check(f"needle in {arm.name}'s jaw", held, detail)

        # The needle has not moved yet: anchor the estimate to the gripper, lift, present it,
        # and it must be seen where the gripper put it.
        ctx.believe(_as_observation(ctx.belief, T_needle), arm.name)
        T_tip_taken = ctx.belief.T_tip_needle.copy()
        self.say(f"{arm.name} lifts the needle")
        up = ctx.phantom.T_world_phantom[:3, 2]
        T_lift = arm.commanded_tip_world()
        T_lift[:3, 3] += LIFT * up
        yield from move_to(ctx.clock, arm, [T_lift], "lift the needle", FINE, joint_ok=False)
        yield from self.run(LocalizeNeedle(ctx, arm.name))
        predicted = arm.tip_world() @ T_tip_taken
        self.check(
            "needle moved with " + arm.name,
            *checks.poses_agree(ctx.belief.T_world_needle, predicted),
        )
        got = np.rad2deg(held_arc_angle(ctx.needle, ctx.belief.T_tip_needle))
        self.report["held_arc_angle_deg"] = float(got)
        self.check(
            "held at the asked arc angle",
            abs(got - asked) <= np.rad2deg(ARC_TOLERANCE),
            f"seen held at {got:.0f}°, asked {asked:.0f}° (± {np.rad2deg(ARC_TOLERANCE):.0f}°)",
        )
        note = "" if which == "driving" else f" ({which}: not the driving hand from above)"
        self.say(f"{arm.name} holds the needle at {got:.0f}°{note}")

    # ---------------------------------------------------------------- helpers
    def _reach_some_angle(self, T_needle: np.ndarray):
        """(arm, grasp, goal) at the asked arc angle, or, for a ``free`` pick-up whose asked
        grasp is out of reach, at the nearest of ``FREE_STEPS`` that is in reach (a needle at
        the block's corner was 0.05° past PSM1's roll limit at the asked angle)."""
        needle = self.context.needle
        lo, hi = needle.tip_angle + END_MARGIN, needle.base_angle - END_MARGIN
        steps = FREE_STEPS if self.free else (0.0,)
        angles = [
            a for a in (self.arc_angle + s for s in steps) if lo <= a <= hi or a == self.arc_angle
        ]
        first = None
        for a in angles:
            grasps = self._grasps(T_needle, a)  # no grasp at all: no other angle helps
            try:
                return self._choose_arm(T_needle, grasps)
            except SkillFailure as e:  # out of reach at this angle
                first = first or e
        raise first

    def _grasps(self, T_needle: np.ndarray, arc_angle: float) -> list[RestingGrasp]:
        """The ways this needle can be taken (from above, or from the side on its edge)."""
        tilt, _ = resting_tilt(self.context, T_needle)
        self.report["needle_tilt_deg"] = float(np.rad2deg(tilt))
        try:
            return resting_grasps(self.context, T_needle, arc_angle)
        except SkillFailure as e:
            raise SkillFailure(f"pick up: the needle is {e.reason}") from None

    def _choose_arm(
        self, T_needle: np.ndarray, grasps: list[RestingGrasp]
    ) -> tuple[ArmHandle, RestingGrasp, np.ndarray]:
        """The named arm, or the first that reaches (calibrated arms first, nearest first),
        with the first of ``grasps`` it reaches, and its grasp pose."""
        ctx = self.context
        paths = [grasp_path(ctx, T_needle, g.T_tip_needle) for g in grasps]
        goal = paths[0][1]
        if self.arm_name is not None:
            if self.arm_name not in ctx.arms:
                raise SkillFailure(f"pick up: no arm named {self.arm_name!r}")
            arms = [ctx.arm(self.arm_name)]
        else:
            arms = sorted(
                ctx.arms.values(),
                key=lambda a: (
                    not a.calibrated,
                    np.linalg.norm(a.base_frame()[:3, 3] - goal[:3, 3]),
                ),
            )
        reasons = {}
        for arm in arms:
            whys = []
            for g, path in zip(grasps, paths, strict=True):
                why = feasible(arm, path)
                if not why:
                    return arm, g, path[1]
                whys.append(why if len(grasps) == 1 else f"{g.hand} hand: {why}")
            reasons[arm.name] = "; ".join(whys)
        if self.arm_name is not None:
            raise SkillFailure(f"needle out of {self.arm_name}'s reach: {reasons[self.arm_name]}")
        said = "; ".join(f"{n}: {r}" for n, r in reasons.items())
        raise SkillFailure(f"needle out of every arm's reach: {said}")

    def _blade_depth_mm(self, goal: np.ndarray) -> float:
        """How far the blade ends go below the (flat) tissue top at the grasp (mm, + = below)."""
        T_ph = self.context.phantom.T_world_phantom
        blade_end = goal[:3, :3] @ np.array([0.0, 0.0, BLADE_BEYOND_TIP]) + goal[:3, 3]
        height = (invert(T_ph) @ np.r_[blade_end, 1.0])[2] - TISSUE_TOP_Z
        return float(-1e3 * height)


def look_for_resting(skill: Skill) -> Waiting:
    """Localise a free needle for ``skill``; refused, look once more after the arms make way
    for where an eye saw needle on the tissue top (an arm may hide it from one eye); when no
    arm stands in the way of that, or no eye saw any, for the tissue under every arm's jaws and
    clevis (a needle lying under an arm is hidden from both eyes). A refusal
    whose best fit lies flat on the tissue, where a resting needle lies, is checked by a look
    primed with that fit (:func:`_resting_answer`). The first refusal is in
    ``skill.report["first_look"]``; a second refusal fails the skill."""
    ctx = skill.context
    try:
        yield from skill.run(LocalizeNeedle(ctx, None))
        return
    except SkillFailure as e:
        first = e
    skill.report["first_look"] = first.reason
    if (yield from _resting_answer(skill)):
        return
    seen = seen_on_tissue(ctx)
    moves = make_way(ctx, seen) if seen is not None else []
    if not moves:  # nothing stands in the way of what an eye saw, or no eye saw any needle:
        # it may lie under an arm's jaws, hidden from both eyes; those move out of the way
        moves = make_way_for(ctx, hidden_behind(ctx, *tissue_top(ctx)))
    if not moves and seen is None:
        raise first
    skill.say("not seen clearly: the arms make way and it is looked at again")
    yield from together(*moves)
    try:
        yield from skill.run(LocalizeNeedle(ctx, None))
    except SkillFailure as second:
        if not (yield from _resting_answer(skill)):
            raise second from None


def _resting_answer(skill: Skill) -> Waiting:
    """True when the last look's refused best fit lies flat on the tissue (``lies_on_tissue``:
    a free needle comes to rest there) and a look primed with it (the arm-prediction check's
    looser outline tolerance) agrees with it and lies there too; that answer is adopted."""
    ctx = skill.context
    T = getattr(ctx.sensor, "last_refused", None)
    if T is None or not lies_on_tissue(ctx, T):
        return False
    yield
    try:
        obs = ctx.sensor.observe(T, prior_checked=True)
    except NeedleNotSeen as e:
        skill.report["resting_look"] = f"refused fit lies on the tissue; primed look: {e.reason}"
        return False
    ok, detail = checks.poses_agree(obs.T_world_needle, T)
    ok = ok and lies_on_tissue(ctx, obs.T_world_needle)
    skill.report["resting_look"] = (
        f"refused fit lies on the tissue; primed look {'agrees' if ok else 'disagrees'} ({detail})"
    )
    if ok:
        ctx.believe(obs, None)
        skill.say("a look primed with the refused fit on the tissue agrees: adopted")
    return ok


def seen_on_tissue(ctx: TaskContext) -> np.ndarray | None:
    """The world point on the flat tissue top under the centre of the needle pixels the last
    look saw (the eye that saw most), or None when no eye saw any (camera model and the
    phantom's known frame)."""
    cams = (ctx.camera.model.left, ctx.camera.model.right)
    px, cam = max(zip(ctx.sensor.seen_pixels(), cams, strict=True), key=lambda pc: len(pc[0]))
    if len(px) < 4:
        return None
    u, v = np.asarray(px, dtype=float).mean(axis=0)
    ray = cam.T_world_cam[:3, :3] @ np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])
    origin = cam.T_world_cam[:3, 3]
    t = ray_meets_plane(origin, ray, *tissue_top(ctx))
    return origin + t * ray if t is not None and t > 0 else None


def tissue_top(ctx: TaskContext) -> tuple[np.ndarray, np.ndarray]:
    """A point of the phantom's flat tissue top and its up normal (world)."""
    T_ph = ctx.phantom.T_world_phantom
    return (T_ph @ np.array([0.0, 0.0, TISSUE_TOP_Z, 1.0]))[:3], T_ph[:3, 2]


def _as_observation(belief, T_world_needle: np.ndarray) -> NeedleObservation:
    """The last estimate as an observation, to re-anchor it to the new holder."""
    return NeedleObservation(
        T_world_needle, belief.stamp, belief.angle_std_deg, belief.position_std_mm, belief.source
    )
