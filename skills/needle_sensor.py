"""The needle sensor skills use: capture a stereo frame and localise the needle in it.

Vision only (images + the calibrated camera model): the localiser's refusal (its reason)
becomes :class:`NeedleNotSeen`. A lost frame (:class:`FrameLost`) or a darkened one (seen in the
image: far darker than the frames before it) is captured again at once, up to
``MAX_BAD_FRAMES`` frames in a row; then the sensor refuses with that reason ("3 frames lost
in a row"), or takes a frame still dark at the limit as the new lighting. ``observe`` runs
inside a skill's tick, so it re-captures instead of waiting; the calibration skill, which owns
its capture, backs off in simulated time instead. The last frame and estimate are kept for
logging; a lost frame clears the last frame.

Task priors (:mod:`suture_bt.perception.needle_prior`) go to the localiser when the caller
knows them: a prior-checked ``previous`` (the pose the holding arm's motion predicts) becomes a
predicted-pose prior within the tolerance the caller checks it to (``checks.poses_agree``), and
a ``holder`` (arm name, its measured tip pose) a held-by prior at the pinch point between its
jaws and, given ``jaw_tolerance_deg``, an across-the-jaws prior (the needle's face as every
grasp of the task holds it), which also tells base from tip when colour cannot. They pick
the right one of the localiser's mirror twins, or make it refuse naming them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from suture_bt.interfaces import FrameLost, StereoCameraInterface
from suture_bt.perception.arc_evidence import arc_hits, metal_masks
from suture_bt.perception.in_hand import JAW_POINT_IN_TIP
from suture_bt.perception.needle_localizer import MIN_DEPTH, NeedleLocalizer
from suture_bt.perception.needle_prior import (
    AcrossJawsPrior,
    HeldPrior,
    NeedlePrior,
    PredictedPosePrior,
)
from suture_bt.perception.pose_fit import NeedleNotFound
from suture_bt.skills.checks import AGREE_ANGLE_DEG, AGREE_POSITION
from suture_bt.skills.context import NeedleNotSeen, NeedleObservation

#: Worst edge residual (px) accepted when the caller checks the answer against a prior (the
#: pose its arm predicts): a needle in a port is partly hidden by the tissue and fits worse,
#: and the prior, not the residual, then guards against a wrong answer.
PRIOR_CHECKED_RMS_PX = 0.9
#: Frames lost or dark in a row before the sensor gives up.
MAX_BAD_FRAMES = 3
#: A frame whose mean brightness is below this share of the good frames' is dark.
DARK_SHARE = 0.6
#: How far (m) the held wire may pass from the pinch point the holder's measured tip pose
#: gives: a few mm while its joint offset is uncalibrated (the default), sub-mm once it is.
HELD_TOLERANCE = 0.004
HELD_TOLERANCE_CALIBRATED = 0.001
#: How far (m, along the arc) the jaw may hold the needle from where the caller's belief
#: says (``HeldPrior.arc_angle``): its grasps put it there within RMS 0.10-0.18 mm, at most
#: 0.81 mm (6 development campaign trials, benchmarks/needle_task_scenes.HELD_PLACE_SPREAD).
#: A bound over that largest miss (until session 36 it was 0.5 mm, and refused needles held
#: within that measured spread of where the belief said); the fit weighs the place at half of
#: it (``perception.prior_term.PLACE_SIGMA_SHARE``). The tree passes no held place yet.
#: The prior's own default, so the two cannot drift apart.
HELD_PLACE_TOL = HeldPrior.arc_tolerance
#: A needle whose centre is predicted nearer the left camera than the localiser's floor
#: (``MIN_DEPTH``, 20 mm) plus this (m) is not worth a look: the localiser refuses it. (With
#: the floor at 50 mm the in-hand check's risen views, 28 and 44 mm away, were refused on every
#: pair that had them.)
RANGE_MARGIN = 0.003


def in_working_range(camera: StereoCameraInterface, T_world_needle: np.ndarray | None) -> bool:
    """Whether a needle predicted at ``T_world_needle`` (None: unknown, True) lies beyond the
    localiser's near floor in front of the left camera."""
    if T_world_needle is None:
        return True
    centre = camera.model.left.to_camera(np.asarray(T_world_needle)[:3, 3][None])[0]
    return bool(centre[2] >= MIN_DEPTH + RANGE_MARGIN)


def brightness(frame) -> float:
    """Mean intensity of the left image (what a dark frame shows)."""
    return float(np.mean(frame.left))


class VisionNeedleSensor:
    """``observe(previous)``: capture, localise, answer in the world frame or refuse.

    ``prior_checked=True`` says the caller will reject an answer that disagrees with
    ``previous``; the localiser may then accept a looser outline fit, and ``previous`` is
    passed as a predicted-pose prior. ``holder`` = (arm name, T_world_tip from its measured
    joints) adds a held-by prior within ``holder_tolerance`` (m) and, with
    ``jaw_tolerance_deg``, an across-the-jaws prior within that angle: the needle's z axis
    along ``held_face`` (world; default against the tip's z axis, as the task's hands hold it).
    """

    def __init__(self, camera: StereoCameraInterface, localizer: NeedleLocalizer | None = None):
        self.camera = camera
        self.localizer = localizer or NeedleLocalizer(camera.model)
        self.last_frame = None
        self.last_estimate = None
        #: The last look's refused best fit (world), when it made one: not an answer.
        self.last_refused: np.ndarray | None = None
        self.calls = 0
        #: Bad frames re-captured so far, as (kind, reason) (kind: "lost" or "dark").
        self.bad_frames: list[tuple[str, str]] = []
        self._reference: float | None = None  # brightness of the last good frame
        self._masks = None  # (frame, its metal masks) for hits()

    def observe(
        self,
        previous: np.ndarray | None = None,
        prior_checked: bool = False,
        holder: tuple[str, np.ndarray] | None = None,
        holder_tolerance: float = HELD_TOLERANCE,
        jaw_tolerance_deg: float | None = None,
        held_face: np.ndarray | None = None,
    ) -> NeedleObservation:
        """Capture and localise (world frame), with the priors the caller's knowledge gives."""
        self.calls += 1
        frame = self.capture()
        self.last_frame, self.last_estimate, self.last_refused = frame, None, None
        T_cam_world = self.camera.model.left.T_cam_world
        prev_cam = None if previous is None else T_cam_world @ np.asarray(previous, dtype=float)
        gates = self.localizer.gates
        if prior_checked and prev_cam is not None:
            gates = replace(gates, max_rms_px=max(gates.max_rms_px, PRIOR_CHECKED_RMS_PX))
        try:
            est = self.localizer.localize(
                frame.left,
                frame.right,
                previous=prev_cam,
                priors=self.priors(
                    previous, prior_checked, holder, holder_tolerance, jaw_tolerance_deg, held_face
                ),
                gates=gates,
            )
        except NeedleNotFound as exc:
            best = getattr(exc, "best", None)
            if best is not None:
                best = self.camera.model.left.T_world_cam @ best
            self.last_refused = best
            raise NeedleNotSeen(str(exc), getattr(exc, "unseen_eye", None), best) from exc
        self.last_estimate = est
        return NeedleObservation(
            est.T_world_needle.copy(),
            frame.stamp,
            float(est.angle_std_deg),
            float(est.position_std_mm),
            "vision",
            {
                "rms_px": float(est.rms_px),
                "total_ms": float(est.timings_ms["total"]),
                "priors": [type(p).__name__ for p in est.priors],
            },
        )

    @staticmethod
    def priors(
        previous: np.ndarray | None,
        prior_checked: bool,
        holder: tuple[str, np.ndarray] | None,
        holder_tolerance: float = HELD_TOLERANCE,
        jaw_tolerance_deg: float | None = None,
        held_face: np.ndarray | None = None,
    ) -> list[NeedlePrior]:
        """The task priors for the localiser from what the caller gave (world frame)."""
        out: list[NeedlePrior] = []
        if prior_checked and previous is not None:
            T = np.asarray(previous, dtype=float)
            out.append(
                PredictedPosePrior(T, AGREE_POSITION, AGREE_ANGLE_DEG, "the arm's prediction")
            )
        if holder is not None:
            arm, T_tip = holder
            T_tip = np.asarray(T_tip, dtype=float)
            pinch = T_tip[:3, :3] @ JAW_POINT_IN_TIP + T_tip[:3, 3]
            out.append(HeldPrior(arm, pinch, holder_tolerance))
            if jaw_tolerance_deg is not None:
                face = -T_tip[:3, 2] if held_face is None else np.asarray(held_face, float)
                out.append(AcrossJawsPrior(arm, face.copy(), jaw_tolerance_deg))
        return out

    def capture(self):
        """A good frame: a lost or dark one is captured again, up to ``MAX_BAD_FRAMES`` in a
        row. All lost: refuse with that reason. Still dark at the limit: the light has
        changed, so the last dark frame becomes the new reference and is used."""
        dark = None
        for _ in range(MAX_BAD_FRAMES):
            try:
                frame = self.camera.capture()
            except FrameLost as exc:
                self.last_frame = None
                self.bad_frames.append(("lost", exc.reason))
                continue
            except Exception as exc:  # noqa: BLE001 - no frame at all is a refusal
                self.last_frame = None
                raise NeedleNotSeen(f"no frame: {exc}") from exc
            level = brightness(frame)
            if self._reference is not None and level < DARK_SHARE * self._reference:
                dark = frame
                self.bad_frames.append(("dark", f"{level:.0f} vs {self._reference:.0f} before"))
                continue
            self._reference = level
            return frame
        if dark is None:
            raise NeedleNotSeen(f"{MAX_BAD_FRAMES} frames lost in a row")
        self._reference = brightness(dark)
        return dark

    def support(self, T_world_needle: np.ndarray, angles: np.ndarray) -> tuple[float, float]:
        """Share of the arc at ``angles`` of a predicted pose seen as metal in the last frame."""
        left, right = self.hits(T_world_needle, angles)
        return tuple(float(h.mean()) if len(h) else 0.0 for h in (left, right))

    def seen_pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the network saw needle in the last frame (full-resolution px per eye)."""
        if self.last_frame is None:
            return np.zeros((0, 2)), np.zeros((0, 2))
        return self.localizer.seen_pixels(self.last_frame.left.shape[0])

    def hits(self, T_world_needle: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per sample of the arc at ``angles`` of a predicted pose: seen as metal (left, right)."""
        if self.last_frame is None:
            raise NeedleNotSeen("no frame captured yet")
        f = self.last_frame
        if self._masks is None or self._masks[0] is not f:  # once per frame
            self._masks = (f, metal_masks((f.left, f.right)))
        return arc_hits(
            (f.left, f.right),
            self.camera.model,
            T_world_needle,
            self.localizer.model,
            angles,
            masks=self._masks[1],
        )
