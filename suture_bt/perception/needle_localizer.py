"""Needle localisation pipeline: stereo images → needle pose with evidence, or NeedleNotFound.

1. Both images, area-downsampled to the network width, go through the CNN in one batch:
   coarse needle mask + base/tip heatmaps (sub-pixel keypoints).
2. Each eye's coarse mask gates a full-resolution colour test (:mod:`needle_masks`,
   :mod:`colour_refine`). A needle the keypoints put nearer than 38 mm is measured from here
   on on the images halved, where it looks as a needle at the working distance does
   (:mod:`near_view`), unless the halved masks say it is not near.
3. The stereo pose fit (:mod:`fit_attempts`, :mod:`pose_fit`) starts from the left keypoints,
   with a depth hint from their stereo disparity, and optionally a warm start from the
   previous estimate; an answer with a clearly different pose of near-equal cost nearby
   (:mod:`rival_probe`) is refused, and so is one whose predicted spread is looser than the
   caller's priors and the tissue's share of the arc allow (:mod:`spread_limits`).
4. The fitted arc's unseen part must be hidden by something (:mod:`exposure_gate`,
   :mod:`unseen_arc`: a jaw or shaft, the border, the tissue where the caller's tissue model
   says it can hide it), and no wire both eyes see may lie deep inside the known tissue; a
   near view that shows only a short piece answers only a clear winner (:mod:`short_tie`);
   an end that meets the tissue may not leave the needle free to slide on into it
   (:mod:`tissue_slide`); else a refusal.
5. The outline cannot tell base from tip: the colour at the fitted ends (the violet swage band
   at the base, :mod:`needle_ends`; :mod:`base_or_tip`) does, else continuity with the previous
   estimate or the holder's jaws; a fit whose arc passes beside the seen band is refused.
Only images and the calibrated camera model are used (no ground truth).
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from suture_bt.compute_threads import set_compute_threads
from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.base_or_tip import BaseTipChooser
from suture_bt.perception.colour_refine import ColourRule, frame_exposure
from suture_bt.perception.exposure_gate import ExposureGate
from suture_bt.perception.fit_attempts import FitAttempts
from suture_bt.perception.near_view import confirms_near, halved, halved_stereo, wants_half
from suture_bt.perception.needle_estimate import NeedleEstimate
from suture_bt.perception.needle_masks import (  # noqa: F401 - the working range, re-exported
    MAX_DEPTH,
    MIN_DEPTH,
    NEAR_UNMEASURED,
    NeedleMasks,
)
from suture_bt.perception.needle_prior import (
    AcrossJawsPrior,
    NeedlePrior,
    PredictedPosePrior,
    check_across_jaws,
    check_held_place,
    check_orientation,
)
from suture_bt.perception.network import (
    INPUT_SIZE,
    NeedleNet,
    frozen_for_inference,
    load_network,
)
from suture_bt.perception.network_reading import (
    MAX_CHORD_MARGIN,
    MIN_KEYPOINT_SCORE,
    NetworkOutput,
    plausible_scores,
    read_network,
    trusted_ends_and_depth,
)
from suture_bt.perception.pose_fit import (
    NeedleNotFound,
    PoseFitter,
)
from suture_bt.perception.short_tie import check_short_tie
from suture_bt.perception.spread_limits import (  # noqa: F401 - the limits, re-exported
    HELD_PIN_TOLERANCE,
    MAX_ANGLE_STD_DEG,
    MAX_ANGLE_STD_DEG_HELD,
    MAX_ANGLE_STD_DEG_UNAIDED,
    check_spread_in_tissue,
)
from suture_bt.perception.stereo_window import Window, right_window
from suture_bt.perception.stray_pieces import refit_without_stray_pieces
from suture_bt.perception.tissue_slide import check_tissue_slide, tissue_slide

#: Left coarse probability over which a pixel may be needle the right eye's window must hold
#: (below the masks' own threshold: the window errs wide).
WINDOW_THRESHOLD = 0.1
#: The fit searches no nearer than this share of the nearest stereo depth (keypoints', masks').
NEAR_SLACK = 0.7


@dataclass(frozen=True)
class _Call:
    """What one ``localize`` call brings to its measurement: the frame's colour rule, the
    warm start, the priors, the gates and when it began and its network finished."""

    rule: ColourRule
    previous: np.ndarray | None
    priors: tuple
    gates: AnswerGates
    t0: float
    t1: float


class _NotNear(Exception):
    """The halved images' masks do not confirm a near needle: measure at full resolution."""


class NeedleLocalizer:
    """Stateless per call except for the optional warm start (``previous``)."""

    def __init__(
        self,
        stereo: StereoCameraModel,
        model: NeedleModel | None = None,
        net: NeedleNet | None = None,
        weights: str | os.PathLike | None = None,
        threads: int | None = None,
        rule: ColourRule | None = None,
        use_free_space: bool = False,
        gates: AnswerGates | None = None,
        tissue: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        """``use_free_space`` adds the pose fit's free-space term (experimental, off by
        default: on the 1080p occluded benchmark it lowered success from 0.43 to 0.37, since
        tissue hides a needle in a port as an arm does); ``gates`` are the limits an answer
        must meet, else NeedleNotFound (:class:`~.answer_gates.AnswerGates`; its defaults
        when not given).

        ``tissue`` (optional task knowledge, world points → bool: where the known phantom may
        hide a needle, :func:`~suture_bt.perception.unseen_arc.tissue_model`) lets the tissue
        hide only there; without it any tissue-coloured pixel may hide the needle (its depth
        is unknown), and only the background exposes a hypothesis. A tissue that also has
        ``pieces`` (:class:`~suture_bt.perception.unseen_arc.PhantomTissue`) gives the fit the
        solid, inside which the arc is hidden (:mod:`~suture_bt.perception.tissue_cut`)."""
        self.stereo = stereo
        self.model = model or NeedleModel()
        self.net = frozen_for_inference(net if net is not None else load_network(weights))
        if threads is not None:
            set_compute_threads(threads)
        self.rule = rule or ColourRule()
        self.use_free_space = use_free_space
        self.gates = gates or AnswerGates()
        self.fitter = PoseFitter(stereo, self.model, depth_range=(MIN_DEPTH, MAX_DEPTH))
        self.tissue = tissue
        self.input_width = INPUT_SIZE[0]
        self.coarse_threshold = 0.3
        #: Whether an answer that runs through a mask piece it does not explain as wire is
        #: fitted again without it (:mod:`~suture_bt.perception.stray_pieces`).
        self.drop_stray_pieces = True
        #: The last call's network output (coarse probabilities, scale), kept whether or not
        #: it answered: a refusal still says where in the images needle was seen.
        self.last_network: tuple[np.ndarray, float] | None = None
        #: Whether the right eye is read only where the left eye's needle can appear
        #: (:mod:`~suture_bt.perception.stereo_window`).
        self.window_right = True
        #: Whether each eye's mask grows along wire the network's coarse mask stopped short
        #: of (:mod:`~suture_bt.perception.wire_growth`).
        self.grow_wire = True
        #: Whether a needle the keypoints put near is measured on the images halved
        #: (:mod:`~suture_bt.perception.near_view`).
        self.halve_near = True
        #: Full-resolution px per px of this localiser's images (2 for its halved copy).
        self.pixel_scale = 1.0

    @property
    def tissue(self) -> Callable[[np.ndarray], np.ndarray] | None:
        """The caller's tissue model (see ``__init__``). Setting it (the phantom was moved)
        also gives the fit the new model's solid."""
        return self._tissue

    @tissue.setter
    def tissue(self, tissue: Callable[[np.ndarray], np.ndarray] | None) -> None:
        self._tissue = tissue
        self.fitter.tissue_solid = getattr(tissue, "pieces", None)

    def base_tip(self, rule: ColourRule | None = None) -> BaseTipChooser:
        """The base-or-tip choice with this localiser's cameras, model, tissue and ``rule``
        (a frame's; default: the nominal)."""
        return BaseTipChooser(self.stereo, self.model, rule or self.rule, self.tissue)

    def network(self, left: np.ndarray, right: np.ndarray):
        """Coarse mask probabilities (2, h, w), keypoints (2, 2, 2) in full-res px, scores,
        full px per coarse px (:func:`~.network_reading.read_network`)."""
        window = self._right_window if self.window_right else None
        return read_network(self.net, left, right, self.input_width, window)

    def _right_window(
        self, prob_left: np.ndarray, scale: float, input_scale: float, shape: tuple[int, int]
    ) -> Window | None:
        """The right eye's network window (:func:`~.stereo_window.right_window`)."""
        depths = (MIN_DEPTH, MAX_DEPTH)
        threshold = WINDOW_THRESHOLD
        return right_window(prob_left, scale, self.stereo, depths, threshold, input_scale, shape)

    def plausible(self, kp: np.ndarray, score: np.ndarray, prob=None, scale: float = 1.0):
        """``score`` with a keypoint zeroed where an eye's two lie farther apart than the
        needle's chord can appear at the nearest working distance
        (:func:`~.network_reading.plausible_scores`)."""
        max_px = MAX_CHORD_MARGIN * self.model.chord * self.stereo.left.fx / NEAR_UNMEASURED
        return plausible_scores(kp, score, max_px, prob, scale, self.coarse_threshold)

    def localize(
        self,
        left: np.ndarray,
        right: np.ndarray,
        previous: np.ndarray | None = None,
        priors: Sequence[NeedlePrior] = (),
        gates: AnswerGates | None = None,
    ) -> NeedleEstimate:
        """Estimate the needle pose; ``previous`` (T_cam_needle) warm-starts the fit and, when
        the swage band is not seen, says which end is the base (a tracked or held needle).

        ``priors`` (world frame, :mod:`needle_prior`: held by an arm, in a port, a predicted
        pose) choose between the fit's candidates (the mirror twins); an image no candidate of
        which agrees with them is refused with a reason naming the prior
        (:class:`~suture_bt.perception.needle_prior.PriorContradicted`). A predicted pose also
        decides base ↔ tip when the swage band does not, like ``previous``.

        ``gates`` replace the localiser's own refusal limits for this call.

        Raises :class:`NeedleNotFound` (with a reason) when the needle is not visible enough,
        including when base and tip cannot be told apart and there is no ``previous``.
        """
        gates = gates or self.gates
        if previous is not None:
            previous = np.asarray(previous, dtype=float)
            if previous.shape != (4, 4) or not np.all(np.isfinite(previous)):
                raise ValueError(
                    f"previous must be a finite 4×4 T_cam_needle, got shape {previous.shape}"
                )
        t0 = time.perf_counter()
        prob, kp, raw_score, scale = self.network(left, right)  # checks the images
        rule = self.rule.at_exposure(frame_exposure(left))
        self.last_network = (prob, scale)
        t1 = time.perf_counter()
        reading = NetworkOutput(prob, kp, raw_score, scale)
        call = _Call(rule, previous, tuple(priors), gates, t0, t1)
        hint = self._hint(reading)
        if self.halve_near:
            if wants_half(hint[2], left.shape):
                try:
                    return self._halved()._measure(
                        (halved(left), halved(right)), reading.halved(), call, confirm_near=True
                    )
                except _NotNear:
                    pass  # the masks put the needle farther: measured at full resolution
                except NeedleNotFound as exc:
                    if not call.priors:
                        exc.reason = f"{exc.reason} (measured on the halved images: near)"
                        exc.args = (exc.reason,)
                        raise
                    # With the task's priors full resolution decides (near_view).
        return self._measure((left, right), reading, call, hint=hint)

    def _hint(self, reading: NetworkOutput) -> tuple:
        """The keypoint scores kept as plausible at this localiser's resolution, and the
        trusted end keypoints and stereo depth they give (:func:`trusted_ends_and_depth`)."""
        score = self.plausible(reading.keypoints, reading.scores, reading.prob, reading.scale)
        return (score, *trusted_ends_and_depth(reading.keypoints, score, self.stereo))

    def _halved(self) -> NeedleLocalizer:
        """This localiser on the halved images (:mod:`near_view`): its cameras at half width
        and height, its fitter's current settings."""
        half = copy.copy(self)
        half.stereo = halved_stereo(self.stereo)
        half.fitter = replace(self.fitter, stereo=half.stereo)
        half.pixel_scale = 2.0 * self.pixel_scale
        return half

    def _measure(
        self,
        images,
        reading: NetworkOutput,
        call: _Call,
        confirm_near: bool = False,
        hint: tuple | None = None,
    ) -> NeedleEstimate:
        """Everything after the network (masks, fit, gates, base or tip) on ``images`` at this
        localiser's resolution. ``confirm_near``: raise :class:`_NotNear` unless the masks
        put the needle near (:func:`~.near_view.confirms_near`), or when they fail. ``hint``:
        :meth:`_hint` of ``reading`` at this resolution, when already made."""
        left, right = images
        prob, kp, raw_score, scale = reading.prob, reading.keypoints, reading.scores, reading.scale
        rule, previous, priors, gates = call.rule, call.previous, call.priors, call.gates
        score, ends, depth = hint or self._hint(reading)
        # The needle's coarse blob is the one at the trusted end keypoints (coarse px).
        anchors = [(kp[e][score[e] >= MIN_KEYPOINT_SCORE] + 0.5) / scale - 0.5 for e in (0, 1)]
        try:
            try:
                views, half_width, depth, near = self._masks(
                    (left, right), rule, prob, scale, depth, anchors
                )
            except NeedleNotFound:
                if depth is None:
                    raise
                # A wrong disparity depth makes the wire look thicker than it can be (a needle
                # seen edge-on folds onto itself): drop the hint and gate at the nearest
                # working distance.
                views, half_width, depth, near = self._masks(
                    (left, right), rule, prob, scale, None, anchors
                )
        except NeedleNotFound:
            if confirm_near:
                raise _NotNear() from None
            raise
        if confirm_near and not confirms_near(near):
            raise _NotNear()
        # Poses much nearer than the stereo depths say are not searched: the working floor is
        # for needles seen that near, not a licence for a near twin of a far one.
        floor = MIN_DEPTH if near is None else max(MIN_DEPTH, NEAR_SLACK * near)
        self.fitter.depth_range = (floor, MAX_DEPTH)
        t2 = time.perf_counter()
        predicted = [p for p in priors if isinstance(p, PredictedPosePrior)]
        if previous is None and predicted:
            previous = self.stereo.left.T_cam_world @ np.asarray(predicted[0].T_world_needle)
        attempts = FitAttempts(self.stereo, self.model, rule, self.fitter, gates)
        fit = attempts((left, right), views, ends, depth, half_width, previous, kp, score, priors)
        inputs = (ends, depth, half_width, previous, kp, score, priors)
        if self.drop_stray_pieces:
            cut = self.fitter.tissue_cut(priors)
            views, fit = refit_without_stray_pieces(
                (left, right), views, fit, attempts, inputs, self.stereo, self.model, cut
            )
        check_spread_in_tissue(
            fit.T_world_needle,
            fit.angle_std_deg,
            priors,
            self.tissue,
            self.model,
            gates.max_angle_std_deg_in_tissue,
        )
        gate = ExposureGate(self.stereo, self.model, rule, self.tissue, gates.max_exposed)
        exposure = gate((left, right), views, fit.T_cam_needle, priors)
        check_short_tie(fit, exposure, gates, priors)
        slide = tissue_slide(gate, (left, right), views, fit.T_cam_needle, priors)
        check_tissue_slide(slide, gates.max_tissue_slide_deg)
        t3 = time.perf_counter()
        jaws = [p for p in priors if isinstance(p, AcrossJawsPrior)]
        T_cam, evidence, decided_by = self.base_tip(rule).orient(
            fit.T_cam_needle, (left, right), views, half_width, previous, jaws
        )
        T_world = self.stereo.left.T_world_cam @ T_cam
        check_orientation(predicted, T_world, decided_by)
        check_across_jaws(jaws, T_world, decided_by)
        check_held_place(priors, T_world, self.model, decided_by)
        t4 = time.perf_counter()
        t0, t1 = call.t0, call.t1
        return NeedleEstimate(
            T_cam_needle=T_cam,
            T_world_needle=T_world,
            rms_px=fit.rms_px,
            inlier_fraction=fit.inlier_fraction,
            ambiguity=fit.ambiguity,
            keypoints_left=kp[0],
            keypoint_scores=raw_score,
            end_evidence=evidence,
            end_decided_by=decided_by,
            timings_ms={
                "network": 1e3 * (t1 - t0),
                "refine": 1e3 * (t2 - t1),
                "fit": 1e3 * (t3 - t2),
                "ends": 1e3 * (t4 - t3),
                "total": 1e3 * (t4 - t0),
            },
            fit=fit,
            masks=(views[0], views[1]),
            priors=priors,
            exposure=exposure,
            pixel_scale=self.pixel_scale,
        )

    def seen_pixels(self, image_height: int) -> tuple[np.ndarray, np.ndarray]:
        """Full-resolution pixels (N×2, u v) where the last call's network saw needle, per
        eye (each coarse pixel over the threshold, at its centre); empty before any call."""
        if self.last_network is None:
            return np.zeros((0, 2)), np.zeros((0, 2))
        prob, scale = self.last_network
        h = int(round(image_height / scale))
        out = []
        for eye in (0, 1):
            ys, xs = np.nonzero(prob[eye][:h] > self.coarse_threshold)
            out.append((np.column_stack([xs, ys]) + 0.5) * scale - 0.5)
        return out[0], out[1]

    def _masks(self, images, rule, prob, scale, depth, anchors=(None, None)):
        """:class:`~suture_bt.perception.needle_masks.NeedleMasks` with this localiser's
        cameras, model, coarse threshold, free-space and wire-growth choices, and the frame's
        colour rule."""
        masks = NeedleMasks(
            self.stereo,
            self.model,
            rule,
            self.coarse_threshold,
            self.use_free_space,
            self.grow_wire,
        )
        return masks(images, prob, scale, depth, anchors)
