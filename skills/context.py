"""What skills are given: the arms (interface views + their PI servos), the camera, the clock,
the known task (port frames, needle model), a needle sensor, and the shared belief.

Everything here is what a real system has: measured joints, commanded values, images and the
calibrated camera model. The runtime (front door) builds it from views that expose only the
robot interface; no simulator object is reachable from a :class:`TaskContext`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from suture_bt.control import PIServo
from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.interfaces import Clock, PSMInterface, StereoCameraInterface
from suture_bt.kinematics import forward_kinematics
from suture_bt.planning import NeedleArc, NeedleArcError, plan_needle_arc
from suture_bt.skills.base import SkillFailure
from suture_bt.transforms import invert


@dataclass
class ArmHandle:
    """One arm as the skills drive it: the interface, its PI servo, its calibration state."""

    name: str
    arm: PSMInterface
    servo: PIServo
    calibrated: bool = False
    #: The last calibration's Δq̂ (joints 1-3) and its report, once calibrated.
    offset_estimate: np.ndarray | None = None
    #: Before calibration: the hidden offsets (N×3) the looks so far leave possible
    #: (:mod:`~suture_bt.skills.offset_evidence`; None: the task's whole bound).
    possible_offsets: np.ndarray | None = None

    def base_frame(self) -> np.ndarray:
        return self.arm.base_frame()

    def tip_world(self) -> np.ndarray:
        """Tip pose in the world from the measured joints plus the offset estimate Δq̂."""
        return self.arm.base_frame() @ forward_kinematics(self.servo.estimated_jp())

    def commanded_tip_world(self) -> np.ndarray:
        """Tip pose the servo is asked for (true-joint desired values, through FK)."""
        return self.arm.base_frame() @ forward_kinematics(self.servo.setpoint_jp())

    def jaw_angle(self) -> float:
        return float(self.arm.jaw.measured_jp()[0])


@dataclass(frozen=True)
class NeedleObservation:
    """One answer of the needle sensor: the pose in the world and its predicted spread."""

    T_world_needle: np.ndarray
    stamp: float
    angle_std_deg: float
    position_std_mm: float
    source: str  # "vision" or "oracle"
    detail: dict = field(default_factory=dict)


class NeedleNotSeen(Exception):
    """The sensor gave no answer; ``reason`` says why (refusal, needle out of view, ...);
    ``unseen_eye``: an image ("left", "right") in which nothing of a needle was seen;
    ``best``: the refused best fit (world) when the localiser made one (not an answer)."""

    def __init__(self, reason: str, unseen_eye: str | None = None, best=None):
        super().__init__(reason)
        self.reason = reason
        self.unseen_eye = unseen_eye
        self.best = best


class NeedleSensor(Protocol):
    """Capture and localise the needle; ``previous`` (world pose) warm-starts the fit."""

    def observe(
        self,
        previous: np.ndarray | None = None,
        prior_checked: bool = False,
        holder: tuple[str, np.ndarray] | None = None,
        holder_tolerance: float = 0.004,
        jaw_tolerance_deg: float | None = None,
        held_face: np.ndarray | None = None,
    ) -> NeedleObservation: ...

    def support(self, T_world_needle: np.ndarray, angles: np.ndarray) -> tuple[float, float]:
        """Share (left, right) of the arc at ``angles`` of a predicted pose that the last
        frame shows as needle."""
        ...

    def seen_pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N×2 per eye, left and right) where the last look saw needle, whether or
        not it answered (a refusal still says where needle was seen)."""
        ...

    def hits(self, T_world_needle: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per sample of the arc at ``angles`` of a predicted pose: shown as needle (left,
        right)."""
        ...


@dataclass
class NeedleBelief:
    """What the tree believes about the needle: last pose, who holds it and how."""

    T_world_needle: np.ndarray
    stamp: float
    source: str
    holder: str | None = None
    #: Needle in the holder's tip frame (compensated tip), when a holder is known.
    T_tip_needle: np.ndarray | None = None
    angle_std_deg: float = float("nan")
    position_std_mm: float = float("nan")
    #: (holder, its tip pose in the world) when this estimate was adopted: while that arm has
    #: not moved, the estimate is as fresh as a new look (uncalibrated arms included).
    seen_at: tuple[str, np.ndarray] | None = None
    #: Two views from different poses of an uncalibrated holder agreed on this estimate
    #: (:mod:`~suture_bt.skills.second_view`); a calibrated holder's needs no second view.
    confirmed: bool = False


@dataclass
class TaskContext:
    """The world as the skills see it (see the module docstring)."""

    arms: dict[str, ArmHandle]
    camera: StereoCameraInterface
    clock: Clock
    phantom: PhantomModel
    needle: NeedleModel
    sensor: NeedleSensor
    #: Oracle ablation only: the true offset of an arm (labelled; None in a real run).
    offset_oracle: Callable[[str], np.ndarray] | None = None
    belief: NeedleBelief | None = None
    #: Every finished skill's report, in order (the logging and rerun layers read these).
    reports: list[dict[str, Any]] = field(default_factory=list)
    #: pair -> {status, reason, t_start, t_end}: the throws' windows (``ThrowScope`` writes).
    throws: dict[int, dict[str, Any]] = field(default_factory=dict)
    #: The arm whose jaw held the needle at the start (its measured jaw says so), before any
    #: estimate names a holder: a drop before the first estimate is still seen.
    start_holder: str | None = None
    #: A world point near which a free needle lies (where it was laid down), for the arms to
    #: make way before it is looked for; not a pose estimate.
    needle_hint: np.ndarray | None = None

    @property
    def oracle(self) -> bool:
        return self.offset_oracle is not None

    def arm(self, name: str) -> ArmHandle:
        try:
            return self.arms[name]
        except KeyError:
            raise KeyError(f"no arm named {name!r} (have {sorted(self.arms)})") from None

    def held_by(self, arm: str, where: str) -> NeedleBelief:
        """The belief, when it has ``arm`` holding the needle with a known in-hand pose; else
        SkillFailure (a skill that needs the needle in that jaw stops before it moves)."""
        b = self.belief
        if b is None or b.holder != arm or b.T_tip_needle is None:
            raise SkillFailure(f"{where}: {arm} is not known to hold the needle")
        return b

    def plan(self, pair: int, where: str) -> NeedleArc:
        """The planned needle circle through ``pair``; SkillFailure with the planner's reason."""
        try:
            return plan_needle_arc(*self.phantom.pair(pair), self.needle)
        except NeedleArcError as e:
            raise SkillFailure(f"{where}: {e.reason}") from None

    def holder(self) -> str | None:
        """The arm believed to hold the needle: the belief's, or before any belief the start's."""
        return self.start_holder if self.belief is None else self.belief.holder

    def predicted_needle(self) -> np.ndarray | None:
        """Where the needle is now if it moved with its holder since the last estimate."""
        b = self.belief
        if b is None:
            return None
        if b.holder is not None and b.T_tip_needle is not None:
            return self.arm(b.holder).tip_world() @ b.T_tip_needle
        return b.T_world_needle.copy()

    def believe(self, obs: NeedleObservation, holder: str | None) -> NeedleBelief:
        """Adopt an observation; with a holder, re-estimate the in-hand transform from it."""
        T_tip = seen_at = None
        if holder is not None:
            T_world_tip = self.arm(holder).tip_world()
            T_tip = invert(T_world_tip) @ obs.T_world_needle
            seen_at = (holder, T_world_tip)
        self.belief = NeedleBelief(
            obs.T_world_needle.copy(),
            obs.stamp,
            obs.source,
            holder,
            T_tip,
            obs.angle_std_deg,
            obs.position_std_mm,
            seen_at,
        )
        return self.belief
