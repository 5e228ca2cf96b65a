"""Skill: localise the needle (free, resting or held) and adopt the estimate as the belief.

A held needle is first presented (:mod:`presentation`): the holding arm turns the arc toward the
cameras, because at the Task 3 start pose it is too close and edge-on to localise. Each answer
must agree with the task: a held needle's wire passes the holder's pinch point. A refusal or a
disagreement moves on to the next presentation pose; after the last one the skill fails with
the reasons it collected. Output: the world pose, its predicted spread and (held) the needle in
the holder's tip frame.
"""

from __future__ import annotations

import numpy as np

from suture_bt.calibration.calibration_pose import offset_box_points
from suture_bt.kinematics import UnreachablePoseError, inverse_kinematics
from suture_bt.perception.in_hand import estimate_in_hand
from suture_bt.perception.needle_prior import AcrossJawsPrior
from suture_bt.planning import to_base
from suture_bt.skills import presentation, second_view
from suture_bt.skills.base import Skill, SkillFailure, Waiting
from suture_bt.skills.context import NeedleBelief, NeedleNotSeen, NeedleObservation, TaskContext
from suture_bt.skills.grasp_offset import offset_from_grasp
from suture_bt.skills.held_priors import held_priors, hold_tolerance
from suture_bt.skills.line_of_sight import make_way
from suture_bt.skills.motion import move_joints, move_to, together
from suture_bt.skills.offset_evidence import offset_grid, seen_offsets, unseen_offsets
from suture_bt.transforms import invert

#: Presentation poses tried before giving up; more for an uncalibrated holder, whose answers
#: need a second view to agree (a report trial's preparation ended after 7: two answers, one
#: unconfirmed, one with its plane 27° from across the jaws, five refusals).
MAX_PRESENTATIONS = 7
MAX_PRESENTATIONS_UNCALIBRATED = 12
#: Refusals in a row after which presentations chosen from a held needle's in-hand belief
#: stop trusting it: the belief is dropped and the rest are chosen for a needle of unknown
#: pose (whole circle). A confidently wrong first estimate (a twin sharing the tip, seen on
#: a campaign trial: 24 mm off at the base) otherwise aims every presentation wrongly.
DOUBT_AFTER = 3
#: Share of the offset bound still possible around a provisional offset from the grasp
#: (dev fits with 0.2 mm / 1° estimate noise: within 0.2° and 0.2 mm of the true offset).
PROVISIONAL_SHARE = 0.4
#: Wrist turns for more views of an uncalibrated holder's needle, per presentation.
MAX_TURNS = 2
#: A presentation whose pinch point is this close to an avoided pose's counts as the same view.
AVOID_RADIUS = 0.008


class LocalizeNeedle(Skill):
    """Localise the needle; ``holder`` names the arm holding it (None: free or resting)."""

    name = "localize needle"

    def __init__(
        self,
        context: TaskContext,
        holder: str | None = None,
        present: bool = True,
        avoid: tuple[np.ndarray, ...] = (),
        earlier: list | None = None,
    ):
        super().__init__(context)
        #: Unconfirmed answers for an uncalibrated holder, (measured joints, T_world_needle):
        #: a later answer that agrees with one of them is confirmed. A caller that looks
        #: several times (the handover) passes one list to all its looks.
        self.earlier: list = [] if earlier is None else earlier
        #: Whether the adopted answer was confirmed by a second view (uncalibrated holder).
        self.confirmed = False
        #: The latest answer no second view confirmed yet, with the tip pose it was seen at.
        self._unconfirmed: tuple[np.ndarray, NeedleObservation] | None = None
        self.holder = holder
        self.present = present
        #: Presentation poses not to use (a caller's second opinion wants another view).
        self.avoid = [np.asarray(T, dtype=float) for T in avoid]
        #: What the looks since the last narrowing saw of an uncalibrated holder's needle:
        #: (joints, an eye that saw nothing or None, the needle pixels per eye).
        self._evidence: list[tuple[np.ndarray, str | None, tuple]] = []

    def program(self) -> Waiting:
        ctx = self.context
        reasons: list[str] = []
        self._earlier_from_belief()
        if self.holder is None or not self.present:  # look from where it is
            obs = yield from self._look_twice(reasons)
            if obs is None:
                where = f"held by {self.holder} " if self.holder else ""
                raise SkillFailure(f"needle {where}not localised: {'; '.join(reasons)}")
            self._adopt(obs)
            return
        arm = ctx.arm(self.holder)
        poses, why = presentation.choose(ctx, arm)
        poses = presentation.untried(poses, self.avoid, AVOID_RADIUS)
        if not poses:
            raise SkillFailure(f"{arm.name} has no reachable presentation pose ({why[:1]})")
        self.report["presentation_poses"] = [T.tolist() for T in poses]
        tried: list[np.ndarray] = []
        limit = MAX_PRESENTATIONS if arm.calibrated else MAX_PRESENTATIONS_UNCALIBRATED
        while len(tried) < limit:
            if not poses:  # further candidates, past those presented
                poses = self._more_poses(arm, tried)
                if not poses:
                    break
            T = poses.pop(0)
            tried.append(T)
            self.say(f"presenting the needle held by {arm.name} ({len(tried)}/{limit})")
            present = move_to(
                ctx.clock, arm, presentation.lifted_first(ctx, arm, T), "present the needle"
            )
            yield from together(present, *make_way(ctx, self._target(T), self.holder))
            obs = yield from self._look_twice(reasons)
            if obs is not None:
                self._adopt(obs)
                return
            if self.narrow_offsets(arm) or self._doubt_belief(len(tried)):
                poses = presentation.untried(presentation.choose(ctx, arm)[0], tried)
                poses = presentation.untried(poses, self.avoid, AVOID_RADIUS)
        if self._unconfirmed is not None:
            self._adopt_unconfirmed(arm)
            return
        raise SkillFailure(f"needle held by {arm.name} not localised: {'; '.join(reasons)}")

    def _adopt_unconfirmed(self, arm) -> None:
        """No two views agreed: the latest answer that passed every check of its own view is
        adopted as an unconfirmed in-hand estimate (carried with the arm's kinematics, as any
        in-hand belief is), so the caller can go on; a handover looks again, and its taker
        only grasps on an answer two views agree on. (Three report trials' preparations
        ended here when every answer but one was a mirror twin.)"""
        T_tip_then, obs = self._unconfirmed
        T_tip_needle = invert(T_tip_then) @ obs.T_world_needle
        self.context.belief = NeedleBelief(
            arm.tip_world() @ T_tip_needle,
            obs.stamp,
            obs.source,
            self.holder,
            T_tip_needle,
            obs.angle_std_deg,
            obs.position_std_mm,
            (self.holder, T_tip_then),
        )
        self.report["unconfirmed"] = True
        self.say(f"needle held by {arm.name}: no two views agreed, last answer kept unconfirmed")

    def _more_poses(self, arm, tried: list[np.ndarray]) -> list[np.ndarray]:
        """The next presentation candidates, none where one was presented or is avoided."""

        def fresh(T: np.ndarray) -> str:
            if not presentation.untried([T], tried) or not presentation.untried(
                [T], self.avoid, AVOID_RADIUS
            ):
                return "presented already"
            return ""

        return presentation.choose(self.context, arm, fresh)[0]

    def narrow_offsets(self, arm) -> bool:
        """After looks at the needle held by an uncalibrated ``arm``: rule out the offsets
        they contradict (kept in the arm's handle for the next presentations): those that
        would have shown the needle to an eye that saw none, and those under which the needle
        an eye saw could not be in the jaw (:mod:`offset_evidence`). True when some were
        ruled out and some are left; evidence that leaves none (the network missed the needle
        or saw something else) is not used."""
        evidence, self._evidence = self._evidence, []
        if arm.calibrated or not evidence:
            return False
        before = offset_grid() if arm.possible_offsets is None else arm.possible_offsets
        left = before
        for q, unseen_eye, seen in evidence:
            if unseen_eye is not None:
                narrower = unseen_offsets(self.context, arm, q, unseen_eye, left)
            else:
                narrower = seen_offsets(self.context, arm, q, seen, left)
            if len(narrower):
                left = narrower
        if len(left) == len(before):
            return False
        arm.possible_offsets = left
        self.report.setdefault("offsets_left", []).append(len(left))
        return True

    def _doubt_belief(self, refused: int) -> bool:
        """After ``DOUBT_AFTER`` refusals in a row, drop an in-hand belief of this holder (the
        presentations chosen from it are not working). True when one was dropped."""
        b = self.context.belief
        if refused < DOUBT_AFTER or b is None or b.holder != self.holder or b.T_tip_needle is None:
            return False
        self.context.belief = None
        self.report["belief_dropped_after"] = refused
        self.say(f"{refused} refusals in a row: presenting as if the needle's pose were unknown")
        return True

    def _target(self, T_present: np.ndarray) -> np.ndarray:
        """Where the needle will be seen: its centre at this presentation (or the pinch)."""
        b = self.context.belief
        if b is not None and b.holder == self.holder and b.T_tip_needle is not None:
            return (T_present @ b.T_tip_needle)[:3, 3]
        return T_present[:3, 3]

    def _look_twice(self, reasons: list[str]) -> Waiting:
        """A look; for a needle held by an uncalibrated arm, an answer only when two views from
        different holder poses agree (:mod:`second_view`): an earlier answer of this skill (or
        of the caller's ``earlier``) carried to this pose, else another view after a wrist
        turn (up to ``MAX_TURNS``). Returns the agreeing answer, or None (``reasons`` says
        why). Each view is answered on its own: a prior from the first would pull the second
        toward a twin."""
        obs = self._look(reasons)
        arm = None if self.holder is None else self.context.arm(self.holder)
        if obs is None or arm is None or arm.calibrated:
            return obs
        q = arm.servo.estimated_jp()
        if self.present:  # the fallback of a presenting look (:meth:`_adopt_unconfirmed`)
            self._unconfirmed = (arm.tip_world(), obs)
        skip = 0
        for turns in range(MAX_TURNS + 1):
            if obs is not None:
                if self._agrees_with_earlier(arm, q, obs):
                    return obs
                self.earlier.append((q, obs.T_world_needle.copy()))
                T_last = obs.T_world_needle
            if turns == MAX_TURNS:
                break
            turn = second_view.wrist_turn(self.context, arm, q, T_last, skip)
            if turn is None:
                break
            q_turn, k = turn
            skip = k + 1
            yield from move_joints(self.context.clock, arm, q_turn, "turn the wrist: another view")
            q = arm.servo.estimated_jp()
            obs = self._look(reasons)
            if obs is not None and self.present:
                self._unconfirmed = (arm.tip_world(), obs)
        reasons.append(f"answer not confirmed by a second view of {arm.name}'s needle")
        return None

    def _earlier_from_belief(self) -> None:
        """An estimate two views already agreed on, of the needle in this (uncalibrated)
        holder's jaw, counts as an earlier view: a new answer that agrees with it carried to
        the new pose is confirmed without a wrist turn."""
        b = self.context.belief
        if self.holder is None or b is None or not b.confirmed or b.holder != self.holder:
            return
        arm = self.context.arm(self.holder)
        if arm.calibrated or b.seen_at is None or b.seen_at[0] != self.holder:
            return
        try:
            q_seen = inverse_kinematics(
                to_base(b.seen_at[1], arm.base_frame()), arm.servo.setpoint_jp()
            )
        except UnreachablePoseError:
            return
        self.earlier.append((q_seen, b.T_world_needle.copy()))

    def _agrees_with_earlier(self, arm, q_now: np.ndarray, obs: NeedleObservation) -> bool:
        """Whether ``obs`` (at joints ``q_now``, the servo's estimate) is an earlier answer
        carried to here for some offset the arm may still have; recorded as a check either way
        when there are any."""
        if not self.earlier:
            return False
        details = []
        for q_then, T_then in self.earlier:
            ok, detail, _ = second_view.agree_under_some_offset(
                arm, q_then, q_now, T_then, obs.T_world_needle
            )
            if ok:
                self.confirmed = True
                self.report["checks"].append(
                    {"check": "two views agree", "ok": True, "detail": detail}
                )
                return True
            details.append(detail)
        self.report["checks"].append(
            {"check": "two views agree", "ok": False, "detail": details[-1]}
        )
        self.report.setdefault("refusals", []).append(f"two views disagree: {details[-1]}")
        return False

    def _offset_from_grasp(self, obs: NeedleObservation) -> None:
        """A confirmed estimate of an uncalibrated holder's needle: the offset that puts its
        jaw on the needle as the task's grasps hold it becomes a provisional Δq̂ in its servo
        (the arm stays put; the keypoint calibration replaces it), and the offsets still
        possible shrink to ``PROVISIONAL_SHARE`` of the bound around it."""
        arm = self.context.arm(self.holder)
        found = offset_from_grasp(
            arm.base_frame(), arm.servo.estimated_jp(), obs.T_world_needle, self.context.needle
        )
        if found is None:
            self.report["offset_from_grasp"] = "no offset within the bound explains the grasp"
            return
        total = np.asarray(arm.servo.offset_estimate, dtype=float)[:3] + found.offset
        arm.servo.set_offset_estimate(total, hold_pose=True)
        arm.offset_estimate = total.copy()
        arm.possible_offsets = offset_box_points(3) * PROVISIONAL_SHARE
        self.report["offset_from_grasp"] = found.summary()
        self.say(f"{arm.name}: provisional offset from its grasp: {found.summary()}")

    def _look(self, reasons: list[str]) -> NeedleObservation | None:
        ctx = self.context
        previous = ctx.predicted_needle()
        held = {}  # the task priors of a held needle, for the localiser
        if self.holder is not None:
            arm = ctx.arm(self.holder)
            held = held_priors(ctx, self.holder)
            tol, tip = hold_tolerance(arm), held["holder"][1]
            jaw_deg, face = held["jaw_tolerance_deg"], held["held_face"]
        try:
            obs = ctx.sensor.observe(previous, **held)
        except NeedleNotSeen as e:
            self._keep_evidence(getattr(e, "unseen_eye", None))
            reasons.append(e.reason)
            self.report.setdefault("refusals", []).append(e.reason)
            return None
        self._keep_evidence(None)
        if self.holder is not None:
            grip = estimate_in_hand(
                obs.T_world_needle,
                np.linalg.inv(arm.base_frame()) @ tip,
                arm.base_frame(),
                ctx.needle,
                max_jaw_distance=tol,
            )
            ok = grip.plausible
            detail = (
                f"wire {grip.blade_distance * 1e3:.1f} mm from {arm.name}'s blades, "
                f"{grip.jaw_distance * 1e3:.1f} mm from its pinch point (limit {tol * 1e3:.0f} mm)"
            )
            self.report["checks"].append(
                {"check": "held by " + arm.name, "ok": ok, "detail": detail}
            )
            if not ok:
                reasons.append(f"answer disagrees with the grasp: {detail}")
                return None
            tilt = across_jaws_deg(obs.T_world_needle, tip, face)
            ok = tilt <= jaw_deg
            detail = f"plane {tilt:.0f}° from across {arm.name}'s jaws (limit {jaw_deg:.0f}°)"
            self.report["checks"].append({"check": "across the jaws", "ok": ok, "detail": detail})
            if not ok:
                reasons.append(f"answer disagrees with the grasp: {detail}")
                return None
        return obs

    def _keep_evidence(self, unseen_eye: str | None) -> None:
        """Keep what this look saw of an uncalibrated holder's needle for ``narrow_offsets``."""
        if self.holder is None:
            return
        arm = self.context.arm(self.holder)
        if not arm.calibrated:
            q = arm.servo.estimated_jp().copy()
            self._evidence.append((q, unseen_eye, self.context.sensor.seen_pixels()))

    def _adopt(self, obs: NeedleObservation) -> None:
        if self.confirmed:
            self._offset_from_grasp(obs)
        belief = self.context.believe(obs, self.holder)
        belief.confirmed = self.confirmed
        self.report["estimate"] = {
            "T_world_needle": obs.T_world_needle.tolist(),
            "angle_std_deg": obs.angle_std_deg,
            "position_std_mm": obs.position_std_mm,
            "source": obs.source,
            "holder": self.holder,
        }
        where = f"held by {self.holder}" if self.holder else "free"
        self.say(
            f"needle {where} at {np.round(1e3 * belief.T_world_needle[:3, 3], 1)} mm "
            f"(spread {obs.angle_std_deg:.2f}°)"
        )


def across_jaws_deg(
    T_world_needle: np.ndarray, T_world_tip: np.ndarray, face: np.ndarray | None = None
) -> float:
    """Angle (deg) of the needle plane's normal from as its grasp holds it: along ``face``
    (world), by default against the tip's z axis (signed: a needle turned face over is 180°
    off)."""
    face = -T_world_tip[:3, 2] if face is None else np.asarray(face, float)
    return AcrossJawsPrior("holder", face).angle_deg(T_world_needle)
