"""The localiser's fit stage: the end hypotheses the images offer, the fit from them, a
refit when the first fails or its ends moved far from every hypothesis (REFIT_MOVED_PX), and
the gates on the answer (RMS, inliers, predicted spread, a rival pose of near-equal cost).

Hypotheses: the keypoints (with their stereo depth), ends that touch an occluder pushed on
behind it (:mod:`occlusion`), a confident keypoint with the visible piece's far end, the
mask's ends measured along it (:mod:`geodesic_ends`); confident keypoints and the swage band
pull the search; the caller's priors seed it (:func:`~.prior_seeds.seed_poses`) and choose
among its candidates (:mod:`pose_fit`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.base_or_tip import occlusion_radius
from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.edge_samples import mask_ends
from suture_bt.perception.geodesic_ends import geodesic_ends
from suture_bt.perception.needle_ends import band_pixels
from suture_bt.perception.needle_prior import PriorContradicted
from suture_bt.perception.needle_projection import end_pixels
from suture_bt.perception.occlusion import anchored_ends, end_is_occluded, extended_ends
from suture_bt.perception.pose_fit import NeedleNotFound, PoseFitResult, PoseFitter
from suture_bt.perception.prior_seeds import seed_poses
from suture_bt.perception.rival_probe import pose_offset, tie_ratio

#: A keypoint this confident anchors its end even when the other end's keypoint is weak
#: (then the other end is sought at, and behind, the visible piece's far end).
STRONG_KEYPOINT_SCORE = 0.5


def _same_pair(a, b, tol_px: float = 3.0) -> bool:
    """Whether two unordered end-pixel pairs coincide within ``tol_px``."""
    a0, a1, b0, b1 = (np.asarray(p, float) for p in (*a, *b))
    d = min(
        max(np.linalg.norm(a0 - b0), np.linalg.norm(a1 - b1)),
        max(np.linalg.norm(a0 - b1), np.linalg.norm(a1 - b0)),
    )
    return bool(d <= tol_px)


@dataclass
class FitAttempts:
    """The fit stage (see the module docstring) with the localiser's cameras, model, colour
    rule and fitter. An answer outside ``gates`` (:class:`~.answer_gates.AnswerGates`) is
    refused: worse than its RMS, explaining less than its share of the edge, looser
    than its angle spread for the priors or its position spread, with a clearly different
    pose within its rival ratio of the cost (:mod:`rival_probe`), or tied within its tie ratio
    with any other clearly different candidate of the fit (a final pose or a probe's)."""

    stereo: StereoCameraModel
    model: NeedleModel
    rule: ColourRule
    fitter: PoseFitter
    gates: AnswerGates = field(default_factory=AnswerGates)

    def __call__(
        self, images, views, ends, depth, half_width, previous, kp, score, priors=()
    ) -> PoseFitResult:
        """Fit from the keypoints (and depth hint), plus end hypotheses behind occluders.

        An end of the visible needle that touches a grey occluder (or the border) may continue
        behind it (:mod:`occlusion`): pushed-out ends join the fit as alternatives. Where one
        keypoint is confident and the other weak, the weak end is likely hidden: it is sought
        at and behind the visible piece's far end. Confident keypoints of both eyes also guide
        the search as a soft prior (:class:`~suture_bt.perception.pose_fit.EndPriorTerm`). A
        failed fit often means a keypoint landed off the needle (e.g. on a jaw) or the disparity
        depth was wrong: it is refit without the depth hint, from the keypoints and from the
        mask's own ends. (Refitting poor fits too, as before, cost 10-15 ms per occluded frame
        for one scene in 200 once the search above was in place.) ``priors`` go to the fitter;
        when every attempt is refused by them, the prior's reason is the refusal.
        """
        left = images[0]
        visible_ends = ends if ends is not None else mask_ends(views[0])
        radius = occlusion_radius(half_width)
        occluded = tuple(
            end_is_occluded(left, views[0], e, radius, self.rule) for e in visible_ends
        )
        behind = extended_ends(visible_ends, occluded)
        for e in (0, 1):
            if score[0, e] >= STRONG_KEYPOINT_SCORE > score[0, 1 - e]:
                h = anchored_ends(kp[0, e], e == 0, views[0])
                if h is not None:
                    behind += [h] + extended_ends(h, (e == 1, e == 0))
        hidden = bool(behind)  # an end touches an occluder or its keypoint is weak
        along = geodesic_ends(views[0])
        if along is not None and not _same_pair(along, visible_ends):
            behind.append(along)
        end_priors = [kp[eye][score[eye] >= STRONG_KEYPOINT_SCORE] for eye in (0, 1)]
        # The violet band marks the base: it guides the search as a keypoint would.
        bands = [band_pixels(img, view) for img, view in zip(images, views, strict=True)]
        for eye in (0, 1):
            if bands[eye] is not None:
                end_priors[eye] = np.concatenate([end_priors[eye], bands[eye].mean(0)[None]])
        end_priors = tuple(end_priors)

        seeds = seed_poses(priors, self.model)
        seeds = self.stereo.left.T_cam_world[None] @ seeds if len(seeds) else None

        def attempt(main, alternatives, depth_hint=None) -> PoseFitResult:
            return self.fitter.fit(
                views[0],
                views[1],
                main,
                depth_hint=depth_hint,
                warm_start=previous,
                alternatives=alternatives,
                end_priors=end_priors,
                hidden_end=hidden,
                priors=priors,
                seeds=seeds,
            )

        fit = None
        contradicted: PriorContradicted | None = None
        try:
            fit = attempt(ends, behind, depth)
        except NeedleNotFound as exc:
            if isinstance(exc, PriorContradicted):
                contradicted = exc
            if ends is None and depth is None:
                raise
        if fit is None and ends is not None:
            # The first fit already searched the occluded-end hypotheses at every depth; new
            # here are the keypoints without the depth hint and the mask's own ends.
            main, others = (ends, [None]) if depth is not None else (None, [])
            try:
                fit = attempt(main, others)
            except PriorContradicted as exc:
                contradicted = exc
            except NeedleNotFound:
                pass
        moved = fit is not None and fit.ends_moved_px > self.gates.refit_moved_px
        if moved and not (hidden or priors):
            fit = self._refit_from_own_ends(fit, attempt)
        if fit is None and contradicted is not None:
            raise contradicted
        if fit is None:
            raise NeedleNotFound("no pose explains the needle's outline (every start failed)")
        self._check(fit, priors)
        return fit

    def _check(self, fit: PoseFitResult, priors) -> None:
        """Raise NeedleNotFound, with the reason, when ``fit`` is outside the gates."""
        g = self.gates
        if fit.rms_px > g.max_rms_px:
            raise NeedleNotFound(
                f"the best pose misses the needle's outline by {fit.rms_px:.2f} px RMS "
                f"(> {g.max_rms_px:.2f}; {100 * fit.inlier_fraction:.0f} % of its edge "
                "explained): too little of the needle is seen clearly",
                best=fit.T_cam_needle.copy(),
            )
        if fit.inlier_fraction < g.min_inlier_fraction:
            raise NeedleNotFound(
                f"the best pose explains only {100 * fit.inlier_fraction:.0f} % of the mask's "
                f"edge (< {100 * g.min_inlier_fraction:.0f} %): the mask holds something else"
            )
        limit = g.angle_std_limit(priors)
        if fit.angle_std_deg > limit:
            raise NeedleNotFound(
                f"the seen part leaves the pose loose: predicted angle spread "
                f"{fit.angle_std_deg:.1f} deg (> {limit:.1f}; position "
                f"{fit.position_std_mm:.1f} mm): too little of the needle's curve is seen"
            )
        if fit.position_std_mm > g.max_position_std_mm:
            raise NeedleNotFound(
                f"the seen outline leaves the needle's position loose: predicted spread "
                f"{fit.position_std_mm:.2f} mm (> {g.max_position_std_mm:.2f}; angle "
                f"{fit.angle_std_deg:.1f} deg): too far or too little seen to place it"
            )
        if fit.rival_offset is not None and fit.rival_ratio <= g.max_rival_ratio:
            mm, deg = fit.rival_offset
            ratio, limit = fit.rival_ratio, g.max_rival_ratio
            raise NeedleNotFound(
                f"another pose {mm:.1f} mm / {deg:.0f} deg away explains the outline almost as "
                f"well (cost {ratio:.2f}x the answer's, limit {limit:.2f}): the seen part does "
                "not pin the pose"
            )
        depth = float(fit.T_cam_needle[2, 3])
        tie_limit = g.tie_limit(depth, priors)
        if fit.tie_ratio <= tie_limit:
            raise NeedleNotFound(
                f"two clearly different poses explain the outline equally well (cost "
                f"{fit.tie_ratio:.4f}x the answer's, limit {tie_limit:.2f} at "
                f"{1e3 * depth:.0f} mm): nothing seen tells them apart"
            )
        if fit.valley_ratio <= g.max_valley_ratio:
            how = "better" if fit.valley_ratio < 1.0 else "almost as well"
            raise NeedleNotFound(
                f"a pose tilted {fit.valley_deg:.0f} deg from the answer explains the outline "
                f"{how} (cost {fit.valley_ratio:.4f}x the answer's, limit "
                f"{g.max_valley_ratio:.3f}): the seen part does not pin the pose's tilt"
            )

    def _refit_from_own_ends(self, fit: PoseFitResult, attempt) -> PoseFitResult:
        """The cheaper of ``fit`` and a fit from its own end pixels over every depth; a refit
        answer keeps ``fit`` as its rival when clearly different (from it and its base ↔ tip
        swap), and ``fit``'s own rival when it is the same pose found again, so a view the
        first fit found ambiguous stays so (the rival gate)."""
        own = tuple(end_pixels(self.stereo.left, fit.T_cam_needle, self.model))
        try:
            again = attempt(own, [])
        except NeedleNotFound:
            return fit
        if not again.cost < fit.cost:
            return fit
        poses = np.stack([again.T_cam_needle, fit.T_cam_needle])
        ratio = tie_ratio(0, poses, np.array([again.cost, fit.cost]), np.ones(2, bool), self.model)
        if not np.isfinite(ratio) and fit.rival_ratio < again.rival_ratio:
            # The same pose found again (cheaper by rounding): the first fit's rival stands.
            return replace(again, rival_ratio=fit.rival_ratio, rival_offset=fit.rival_offset)
        if not ratio < again.rival_ratio:
            return again
        return replace(again, rival_ratio=ratio, rival_offset=pose_offset(poses[1], poses[0]))
