"""Needle localisation pipeline: stereo images → needle pose with evidence, or NeedleNotFound.

1. Both images, area-downsampled to the network width, go through the CNN in one batch:
   coarse needle mask + base/tip heatmaps (sub-pixel keypoints).
2. Each eye's coarse mask gates a full-resolution colour test (:mod:`needle_masks`,
   :mod:`colour_refine`).
3. The stereo pose fit (:mod:`fit_attempts`, :mod:`pose_fit`) starts from the left keypoints,
   with a depth hint from their stereo disparity, and optionally a warm start from the
   previous estimate; an answer with a clearly different pose of near-equal cost nearby
   (:mod:`rival_probe`) is refused, and so is one whose predicted spread is looser than the
   caller's priors and the tissue's share of the arc allow (:mod:`spread_limits`).
4. The fitted arc's unseen part must be hidden by something (:mod:`exposure_gate`,
   :mod:`unseen_arc`: a jaw or shaft, the border, the tissue where the caller's tissue model
   says it can hide it), and no wire both eyes see may lie deep inside the known tissue; else
   a refusal.
5. The outline cannot tell base from tip: the colour at the fitted ends (the violet swage band
   at the base, :mod:`needle_ends`; :mod:`base_or_tip`) does, else continuity with the previous
   estimate or the holder's jaws; a fit whose arc passes beside the seen band is refused.
Only images and the calibrated camera model are used (no ground truth).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence

import cv2
import numpy as np
import torch

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.base_or_tip import BaseTipChooser
from suture_bt.perception.colour_refine import ColourRule, frame_exposure
from suture_bt.perception.exposure_gate import MAX_EXPOSED, ExposureGate
from suture_bt.perception.fit_attempts import (  # noqa: F401 - gates, re-exported
    MAX_POSITION_STD_MM,
    MAX_RIVAL_RATIO,
    MAX_RMS_PX,
    MAX_TIE_RATIO,
    MIN_INLIER_FRACTION,
    REFIT_MOVED_PX,
    STRONG_KEYPOINT_SCORE,
    FitAttempts,
)
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
    OUTPUT_STRIDE,
    NeedleNet,
    decode_ends,
    frozen_for_inference,
    load_network,
)
from suture_bt.perception.pose_fit import (
    NeedleNotFound,
    PoseFitResult,
    PoseFitter,
)
from suture_bt.perception.spread_limits import (  # noqa: F401 - the limits, re-exported
    HELD_PIN_TOLERANCE,
    MAX_ANGLE_STD_DEG,
    MAX_ANGLE_STD_DEG_HELD,
    MAX_ANGLE_STD_DEG_IN_TISSUE,
    MAX_ANGLE_STD_DEG_UNAIDED,
    angle_std_limit,
    check_spread_in_tissue,
)
from suture_bt.perception.unseen_arc import ArcExposure

#: A keypoint heatmap peak below this probability is not trusted (the mask's ends are used).
MIN_KEYPOINT_SCORE = 0.15
#: Slack on how far apart one needle's two end keypoints can be (its chord seen at MIN_DEPTH).
MAX_CHORD_MARGIN = 1.2
#: Base and tip keypoints closer than this (full-resolution px) are not trusted as two ends.
MIN_END_SEPARATION_PX = 8.0
#: The fit searches no nearer than this share of the nearest stereo depth (keypoints', masks').
NEAR_SLACK = 0.7


def _net_input(rgb: np.ndarray, width: int) -> tuple[np.ndarray, float]:
    """Area-downsample to ``width`` (aspect kept), pad rows to a multiple of 16; scale."""
    H, W = rgb.shape[:2]
    s = width / W
    h = int(round(H * s))
    small = cv2.resize(rgb, (width, h), interpolation=cv2.INTER_AREA)
    hp = int(np.ceil(h / 16) * 16)
    if hp != h:
        small = np.concatenate([small, np.zeros((hp - h, width, 3), small.dtype)], 0)
    return small, s


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
        max_rms_px: float = MAX_RMS_PX,
        max_angle_std_deg: float = MAX_ANGLE_STD_DEG,
        max_angle_std_deg_held: float = MAX_ANGLE_STD_DEG_HELD,
        tissue: Callable[[np.ndarray], np.ndarray] | None = None,
        max_exposed: float = MAX_EXPOSED,
    ) -> None:
        """``use_free_space`` adds the pose fit's free-space term (experimental, off by
        default: on the 1080p occluded benchmark it lowered success from 0.43 to 0.37, since
        tissue hides a needle in a port as an arm does); ``max_rms_px`` is the worst final
        edge residual accepted and ``max_angle_std_deg`` the loosest predicted angle spread
        when priors are given (else NeedleNotFound; ``max_angle_std_deg_held`` when a
        calibrated held-by prior pins the arc; scaled down without priors, see
        :meth:`_angle_std_limit`).

        ``tissue`` (optional task knowledge, world points → bool: where the known phantom may
        hide a needle, :func:`~suture_bt.perception.unseen_arc.tissue_model`) lets the tissue
        hide only there; without it any tissue-coloured pixel may hide the needle (its depth
        is unknown), and only the background exposes a hypothesis. A tissue that also has
        ``pieces`` (:class:`~suture_bt.perception.unseen_arc.PhantomTissue`) gives the fit the
        solid, inside which the arc is hidden (:mod:`~suture_bt.perception.tissue_cut`).
        ``max_exposed`` (m of arc): see :data:`MAX_EXPOSED` (inf: no check)."""
        self.stereo = stereo
        self.model = model or NeedleModel()
        self.net = frozen_for_inference(net if net is not None else load_network(weights))
        if threads is not None:
            torch.set_num_threads(threads)
        self.rule = rule or ColourRule()
        self.use_free_space = use_free_space
        self.max_rms_px = max_rms_px
        self.max_angle_std_deg = max_angle_std_deg
        self.max_angle_std_deg_held = max_angle_std_deg_held
        #: Without priors, the loosest spread (deg) answered for an arc the tissue hides in part.
        self.max_angle_std_deg_in_tissue = MAX_ANGLE_STD_DEG_IN_TISSUE
        #: A clearly different pose within this ratio of the answer's cost refuses it.
        self.max_rival_ratio = MAX_RIVAL_RATIO
        #: A clearly different candidate within this ratio of the answer's cost is a tie: refused.
        self.max_tie_ratio = MAX_TIE_RATIO
        #: An answer whose predicted arc-centre spread exceeds this (mm) is refused.
        self.max_position_std_mm = MAX_POSITION_STD_MM
        #: An answer whose ends moved farther (px) from every end hypothesis is refit from them.
        self.refit_moved_px = REFIT_MOVED_PX
        self.max_exposed = max_exposed
        self.fitter = PoseFitter(stereo, self.model, depth_range=(MIN_DEPTH, MAX_DEPTH))
        self.tissue = tissue
        self.input_width = INPUT_SIZE[0]
        self.coarse_threshold = 0.3
        #: The last call's network output (coarse probabilities, scale), kept whether or not
        #: it answered: a refusal still says where in the images needle was seen.
        self.last_network: tuple[np.ndarray, float] | None = None

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
        """Coarse mask probabilities (2, h, w), keypoints (2, 2, 2) in full-res px, scores."""
        for name, img in (("left", left), ("right", right)):
            if img is None or img.ndim != 3 or img.shape[2] != 3 or img.size == 0:
                shape = None if img is None else img.shape
                raise ValueError(f"{name} image must be H×W×3 RGB, got {shape}")
        a, s = _net_input(left, self.input_width)
        b, _ = _net_input(right, self.input_width)
        x = torch.from_numpy(np.stack([a, b])).permute(0, 3, 1, 2).float().div_(255.0)
        x = x.contiguous(memory_format=torch.channels_last)
        with torch.inference_mode():
            # One eye at a time: the same outputs as one batch of both (bitwise), faster on
            # a CPU (one eye's activations stay in cache: 28 against 36 ms).
            out = torch.cat([self.net(x[i : i + 1]) for i in range(len(x))])
        prob = torch.sigmoid(out[:, 0]).numpy()
        kp, score = decode_ends(out[:, 1], out[:, 2])
        kp_full = ((kp + 0.5) * OUTPUT_STRIDE) / s - 0.5
        return prob, kp_full, score, OUTPUT_STRIDE / s

    def _plausible(
        self,
        kp: np.ndarray,
        score: np.ndarray,
        prob: np.ndarray | None = None,
        scale: float = 1.0,
    ) -> np.ndarray:
        """Scores with one keypoint of an eye zeroed when the two are farther apart than the
        needle's chord can appear (at the nearest working distance): one of them then sits on
        something else, e.g. a jaw tip, and would pick the wrong blob as the needle. The one
        dropped lies on the smaller blob of the coarse mask ``prob`` (``scale``: full px per
        coarse px) — a jaw tip is a speck beside the needle's arc — or, on a tie or without
        ``prob``, is the weaker (development in_port #16 of seed 1000: the stronger, 0.41
        against 0.17, sat on the other arm's jaw tip)."""
        max_px = MAX_CHORD_MARGIN * self.model.chord * self.stereo.left.fx / NEAR_UNMEASURED
        out = score.copy()
        for eye in (0, 1):
            if out[eye].min() >= MIN_KEYPOINT_SCORE:
                if np.linalg.norm(kp[eye, 0] - kp[eye, 1]) > max_px:
                    areas = None if prob is None else self._blob_areas(prob[eye], kp[eye], scale)
                    if areas is None or areas[0] == areas[1]:
                        out[eye, int(np.argmin(out[eye]))] = 0.0
                    else:
                        out[eye, int(np.argmin(areas))] = 0.0
        return out

    def _blob_areas(self, prob: np.ndarray, kp: np.ndarray, scale: float) -> np.ndarray:
        """Area (coarse px) of the coarse mask's blob each keypoint (2, 2; full px) lies on
        (0: on none)."""
        m = (prob > self.coarse_threshold).astype(np.uint8)
        _, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        out = np.zeros(len(kp))
        h, w = lab.shape
        for i, (u, v) in enumerate((np.asarray(kp, float) + 0.5) / scale - 0.5):
            x, y = int(round(u)), int(round(v))
            win = lab[max(y - 2, 0) : min(y + 3, h), max(x - 2, 0) : min(x + 3, w)]
            labels = win[win > 0]
            if len(labels):
                out[i] = stats[labels, cv2.CC_STAT_AREA].max()
        return out

    def _ends_and_depth(self, kp: np.ndarray, score: np.ndarray):
        """Left (base, tip) pixels when trusted, and a depth hint from their disparity.

        The needle's two ends look alike, so the heads may both fire on one end (then the fit
        finds the ends from the mask) or swap between the eyes (pairs are matched by row).
        """
        ends = depth = None
        if score[0].min() < MIN_KEYPOINT_SCORE:
            return None, None
        if np.linalg.norm(kp[0, 0] - kp[0, 1]) < MIN_END_SEPARATION_PX:
            return None, None
        ends = (kp[0, 0], kp[0, 1])
        if score[1].min() >= MIN_KEYPOINT_SCORE:
            right = kp[1]
            if np.abs(kp[0, :, 1] - right[::-1, 1]).sum() < np.abs(kp[0, :, 1] - right[:, 1]).sum():
                right = right[::-1]
            disp = kp[0, :, 0] - right[:, 0]
            if np.all(disp > 1.0):
                depth = float(np.mean(self.stereo.left.fx * self.stereo.baseline / disp))
                if not MIN_DEPTH <= depth <= MAX_DEPTH:
                    depth = None  # implausible disparity (ends mismatched between the eyes)
        return ends, depth

    def localize(
        self,
        left: np.ndarray,
        right: np.ndarray,
        previous: np.ndarray | None = None,
        priors: Sequence[NeedlePrior] = (),
    ) -> NeedleEstimate:
        """Estimate the needle pose; ``previous`` (T_cam_needle) warm-starts the fit and, when
        the swage band is not seen, says which end is the base (a tracked or held needle).

        ``priors`` (world frame, :mod:`needle_prior`: held by an arm, in a port, a predicted
        pose) choose between the fit's candidates (the mirror twins); an image no candidate of
        which agrees with them is refused with a reason naming the prior
        (:class:`~suture_bt.perception.needle_prior.PriorContradicted`). A predicted pose also
        decides base ↔ tip when the swage band does not, like ``previous``.

        Raises :class:`NeedleNotFound` (with a reason) when the needle is not visible enough,
        including when base and tip cannot be told apart and there is no ``previous``.
        """
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
        score = self._plausible(kp, raw_score, prob, scale)
        ends, depth = self._ends_and_depth(kp, score)
        # The needle's coarse blob is the one at the trusted end keypoints (coarse px).
        anchors = [(kp[e][score[e] >= MIN_KEYPOINT_SCORE] + 0.5) / scale - 0.5 for e in (0, 1)]
        try:
            views, half_width, depth, near = self._masks(
                (left, right), rule, prob, scale, depth, anchors
            )
        except NeedleNotFound:
            if depth is None:
                raise
            # A wrong disparity depth makes the wire look thicker than it can be (a needle seen
            # edge-on folds onto itself): drop the hint and gate at the nearest working distance.
            views, half_width, depth, near = self._masks(
                (left, right), rule, prob, scale, None, anchors
            )
        # Poses much nearer than the stereo depths say are not searched: the working floor is
        # for needles seen that near, not a licence for a near twin of a far one.
        floor = MIN_DEPTH if near is None else max(MIN_DEPTH, NEAR_SLACK * near)
        self.fitter.depth_range = (floor, MAX_DEPTH)
        t2 = time.perf_counter()
        priors = tuple(priors)
        predicted = [p for p in priors if isinstance(p, PredictedPosePrior)]
        if previous is None and predicted:
            previous = self.stereo.left.T_cam_world @ np.asarray(predicted[0].T_world_needle)
        fit = self._fit(
            (left, right), rule, views, ends, depth, half_width, previous, kp, score, priors
        )
        check_spread_in_tissue(
            fit.T_world_needle,
            fit.angle_std_deg,
            priors,
            self.tissue,
            self.model,
            self.max_angle_std_deg_in_tissue,
        )
        exposure = self._exposure((left, right), rule, views, fit.T_cam_needle, priors)
        t3 = time.perf_counter()
        jaws = [p for p in priors if isinstance(p, AcrossJawsPrior)]
        T_cam, evidence, decided_by = self.base_tip(rule).orient(
            fit.T_cam_needle, (left, right), views, half_width, previous, jaws
        )
        check_orientation(predicted, self.stereo.left.T_world_cam @ T_cam, decided_by)
        check_across_jaws(jaws, self.stereo.left.T_world_cam @ T_cam, decided_by)
        check_held_place(priors, self.stereo.left.T_world_cam @ T_cam, self.model, decided_by)
        t4 = time.perf_counter()
        return NeedleEstimate(
            T_cam_needle=T_cam,
            T_world_needle=self.stereo.left.T_world_cam @ T_cam,
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

    def _exposure(self, images, rule, views, T_cam: np.ndarray, priors) -> ArcExposure:
        """:class:`~suture_bt.perception.exposure_gate.ExposureGate` with this localiser's
        cameras, model, tissue model and exposure limit, and the frame's colour rule."""
        gate = ExposureGate(self.stereo, self.model, rule, self.tissue, self.max_exposed)
        return gate(images, views, T_cam, priors)

    def _masks(self, images, rule, prob, scale, depth, anchors=(None, None)):
        """:class:`~suture_bt.perception.needle_masks.NeedleMasks` with this localiser's
        cameras, model, coarse threshold and free-space choice, and the frame's colour rule."""
        masks = NeedleMasks(
            self.stereo, self.model, rule, self.coarse_threshold, self.use_free_space
        )
        return masks(images, prob, scale, depth, anchors)

    def _fit(
        self, images, rule, views, ends, depth, half_width, previous, kp, score, priors=()
    ) -> PoseFitResult:
        """:class:`~suture_bt.perception.fit_attempts.FitAttempts` with this localiser's
        cameras, model, fitter and gates (the spread limit for these priors), and the frame's
        colour rule."""
        attempts = FitAttempts(
            self.stereo,
            self.model,
            rule,
            self.fitter,
            self.max_rms_px,
            self._angle_std_limit(priors),
            self.max_rival_ratio,
            self.max_position_std_mm,
            self.max_tie_ratio,
            self.refit_moved_px,
        )
        return attempts(images, views, ends, depth, half_width, previous, kp, score, priors)

    def _angle_std_limit(self, priors) -> float:
        """The loosest predicted angle spread answered for these priors
        (:func:`~suture_bt.perception.spread_limits.angle_std_limit`)."""
        return angle_std_limit(priors, self.max_angle_std_deg, self.max_angle_std_deg_held)
