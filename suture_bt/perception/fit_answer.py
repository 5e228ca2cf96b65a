"""The pose fit's result for its chosen answer: the pose with the evidence measured on every
edge ray (residual, inliers, spread, rival, tie, how far its ends moved). Split from
:mod:`pose_fit` (one concept a module), which chooses the answer."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from suture_bt.perception.edge_residuals import residuals
from suture_bt.perception.fit_result import PoseFitResult
from suture_bt.perception.fit_solver import pose_uncertainty
from suture_bt.perception.fit_starts import ends_moved
from suture_bt.perception.needle_projection import end_pixels, params_to_pose
from suture_bt.perception.prior_term import PriorTerm
from suture_bt.perception.rival_probe import FitRays, oblique_slides, rival, tie_ratio
from suture_bt.perception.valley_probe import valley_ratio

if TYPE_CHECKING:
    from suture_bt.perception.fit_search import StartSearch


def answer_result(
    search: StartSearch,
    xf: np.ndarray,
    cf: np.ndarray,
    choice: tuple,
    polish: Sequence,
    ambiguity: float,
) -> PoseFitResult:
    """The fit's result when it answers row ``b`` of its polished and probed candidates
    ``xf`` (costs ``cf``). ``search`` is the fit's :class:`~.fit_search.StartSearch` (its
    fitter, edge rays and the end hypotheses it started from); ``choice`` is (b, which rows
    the priors allow, their misses or None, which rows are near enough to be rivals),
    ``polish`` the polish's terms (its prior term among them, if any), ``ambiguity`` the
    polish's cost gap."""
    fitter, rays = search.fitter, search.rays
    b, ok, misses, near = choice
    cam, model = fitter.stereo.left, fitter.model
    poses = params_to_pose(xf, cam, model)
    rival_ratio, rival_offset = rival(b, poses, cf, ok & near & ~oblique_slides(b, poses))
    tie = tie_ratio(b, poses, cf, ok, model)
    T = poses[b]
    r, _ = residuals(T[None], rays, model)
    r = r[0]
    inl = np.abs(r) < 1.5
    rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else float("inf")
    # The polish's own prior term (HeldPlaceTerm, a subclass, is the search's).
    prior_term = next((t for t in polish if type(t) is PriorTerm), None)
    ang_std, pos_std = pose_uncertainty(
        xf[b], rays, fitter.stereo, model, 1.0, fitter.final_loss, prior_term
    )
    valley, valley_deg = float("inf"), float("nan")
    if fitter.probe_valley:
        fit_rays = FitRays(rays, search.coarse, search.mid)
        valley, valley_deg = valley_ratio(
            xf[b], float(cf[b]), fit_rays, fitter.stereo, model, polish, fitter.final_loss
        )
    return PoseFitResult(
        T_cam_needle=T,
        T_world_needle=cam.T_world_cam @ T,
        params=xf[b],
        cost=float(cf[b]),
        rms_px=rms,
        inlier_fraction=float(inl.mean()),
        n_edge_points=(len(search.el), len(search.er)),
        ambiguity=ambiguity,
        candidates=list(poses),
        candidate_costs=tuple(float(v) for v in cf),
        angle_std_deg=ang_std,
        position_std_mm=pos_std,
        prior_misses=() if misses is None else tuple(float(m) for m in misses[b]),
        rival_ratio=rival_ratio,
        rival_offset=rival_offset,
        tie_ratio=tie,
        valley_ratio=valley,
        valley_deg=valley_deg,
        ends_moved_px=ends_moved(np.asarray(end_pixels(cam, T, model)), search.tried),
    )
