"""Where one pose fit's search begins: its edge rays (all, and the coarse and mid subsets), its
extra terms, and the cheapest starts of each end hypothesis. Split from :mod:`pose_fit` (one
concept a module); the LM stages and the decision to search again stay there."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from suture_bt.perception.edge_kernel import edge_normal_equations
from suture_bt.perception.edge_residuals import EdgeRays, edge_rays
from suture_bt.perception.edge_samples import balanced, farthest_pair, subsample
from suture_bt.perception.entry_starts import entry_starts, seen_at_right_end
from suture_bt.perception.fit_solver import FD_STEPS, robust_cost
from suture_bt.perception.fit_starts import ends_moved
from suture_bt.perception.fit_terms import EndPriorTerm, FreeSpaceTerm
from suture_bt.perception.mask_view import MaskView, edge_points
from suture_bt.perception.needle_prior import NeedlePrior, port_planes
from suture_bt.perception.needle_projection import end_pixels, params_to_pose, pose_to_params
from suture_bt.perception.prior_term import HeldPlaceTerm
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.tissue_cut import TissueCut

if TYPE_CHECKING:  # pose_fit imports this module
    from suture_bt.perception.pose_fit import PoseFitter


@dataclass
class StartSearch:
    """One fit's edge rays and extra terms, and the end hypotheses searched so far (``tried``,
    (base, tip) left pixels in order). ``fitter`` is the :class:`~pose_fit.PoseFitter` whose
    settings, start grid (``_starts``) and tissue solid (``_with_solid``) it uses (imported
    for type checking only: :mod:`pose_fit` imports this module)."""

    fitter: PoseFitter
    rng: np.random.Generator
    el: np.ndarray
    er: np.ndarray
    rays: EdgeRays
    coarse: EdgeRays
    mid: EdgeRays
    ports: list
    terms: list
    coarse_w: np.ndarray
    tried: list = field(default_factory=list)

    @classmethod
    def begin(
        cls,
        fitter: PoseFitter,
        left: MaskView,
        right: MaskView,
        end_priors: tuple[np.ndarray, np.ndarray] | None,
        priors: Sequence[NeedlePrior],
    ) -> StartSearch:
        """The search of ``fitter`` on these masks (its edge points drawn with its ``seed``);
        raise NeedleNotFound when an eye has fewer than ``min_edge_points`` of them."""
        rng = np.random.default_rng(fitter.seed)
        el, er = edge_points(left), edge_points(right)
        if len(el) < fitter.min_edge_points or len(er) < fitter.min_edge_points:
            raise NeedleNotFound(
                f"too few needle edge points (left {len(el)}, right {len(er)}, "
                f"need {fitter.min_edge_points} each)"
            )
        el = subsample(el, fitter.max_points_per_eye, rng)
        er = subsample(er, fitter.max_points_per_eye, rng)
        rays = edge_rays(fitter.stereo, el, er)
        # The tissue hides the arc inside it: the known solid, and for a needle in a port the
        # space below the port's surface.
        ports = port_planes(priors)
        rays.cut = TissueCut.from_ports(ports, fitter.stereo.left.T_cam_world, fitter.model)
        nl = len(el)
        coarse = rays.subset(balanced(nl, len(er), fitter.coarse_points_per_eye, rng))
        mid = rays.subset(balanced(nl, len(er), fitter.mid_points_per_eye, rng))
        cam = fitter.stereo.left
        terms = [FreeSpaceTerm(fitter.stereo, fitter.model, (left, right))]
        if end_priors is not None:
            terms.append(EndPriorTerm(fitter.stereo, fitter.model, end_priors))
        if priors:
            terms.append(HeldPlaceTerm(priors, cam.T_cam_world, fitter.model))
        terms = [t for t in terms if t]
        coarse_w = np.concatenate(
            [np.ones(len(coarse))] + [t.column_weights(len(coarse)) for t in terms]
        )
        return cls(fitter, rng, el, er, rays, coarse, mid, ports, terms, coarse_w)

    def first_starts(
        self,
        endpoints_left: tuple[np.ndarray, np.ndarray] | None,
        depth_hint: float | None,
        warm_start: np.ndarray | None,
        alternatives: Sequence[tuple[np.ndarray, np.ndarray] | None],
        seeds: np.ndarray | None,
    ) -> np.ndarray:
        """The first stage's starts (see :meth:`~pose_fit.PoseFitter.fit`): the main
        hypothesis's ``n_keep`` best, each alternative's ``n_keep_alternative`` best, the warm
        start, the ``n_keep`` best ``seeds``, and with a tissue solid the best of the wire
        entering it at an end of the outline; raise NeedleNotFound when there are none. With
        a tissue solid, the rays measure to the arc it leaves seen from here on."""
        f = self.fitter
        cam = f.stereo.left
        parts = [self.best_starts(endpoints_left, depth_hint, f.n_keep)]
        parts += [self.best_starts(e, None, f.n_keep_alternative) for e in alternatives]
        if warm_start is not None:
            parts.append(pose_to_params(np.asarray(warm_start)[None], cam, f.model))
        if seeds is not None and len(seeds):
            parts.append(self.lowest(pose_to_params(np.asarray(seeds), cam, f.model), f.n_keep))
        if f.tissue_solid:
            cut = f._with_solid(self.ports)
            # The solid hides the arc from here on: the image's first starts were chosen
            # without it (with it, far starts half inside the tissue crowded out the right
            # ones on development scenes of a free needle). The outline may end where the wire
            # enters the tissue (own rng: the same draws).
            self.rays.cut = self.coarse.cut = self.mid.cut = cut
            own = np.random.default_rng(f.seed + 1)
            ends, right_ends = farthest_pair(self.el, own), farthest_pair(self.er, own)
            at_end = seen_at_right_end(f.stereo, right_ends)
            entry = entry_starts(ends, cam, cut, f.model, at_end)
            if len(entry):
                parts.append(self.lowest(pose_to_params(entry, cam, f.model), f.n_keep_entry))
        starts = np.concatenate(parts)
        if not len(starts):
            raise NeedleNotFound("no feasible pose hypothesis from the needle's end points")
        return starts

    def reseed_starts(self, x: np.ndarray, cost: np.ndarray, rival_ratio: float) -> np.ndarray:
        """Starts of the second search: the ``n_reseed`` best from the end pixels and depth of
        the cheapest row of ``x`` (second-stage parameters with their ``cost``), and as many
        from a clearly different rival's when it costs at most ``rival_ratio`` times more."""
        f = self.fitter
        cam = f.stereo.left
        best = f._diverse(x, cost, 2)  # rows of x (not the prior ``seeds``)
        if len(best) > 1 and not cost[best[1]] <= rival_ratio * cost[best[0]]:
            best = best[:1]
        st = []
        for T_best in params_to_pose(x[best], cam, f.model):
            ends = tuple(end_pixels(cam, T_best, f.model))
            st.append(self.best_starts(ends, float(T_best[2, 3]), f.n_reseed))
        return np.concatenate(st)

    def best_starts(self, ends, hint, n: int) -> np.ndarray:
        """The n lowest-cost feasible starts (coarse edge subset) for one end hypothesis
        (None: the left outline's farthest pair), which joins ``tried``."""
        if ends is None:
            ends = farthest_pair(self.el, self.rng)
        ub, ut = (np.asarray(e, float) for e in ends)
        self.tried.append((ub, ut))
        return self.lowest(self.fitter._starts(ub, ut, hint), n)

    def lowest(self, st: np.ndarray, n: int) -> np.ndarray:
        """The n lowest-cost feasible rows of ``st`` on the coarse edge subset."""
        model, coarse = self.fitter.model, self.coarse
        T0 = params_to_pose(st, self.fitter.stereo.left, model)
        r0 = edge_normal_equations(T0, None, FD_STEPS, coarse, model, 3.0, "cauchy", grid=12)[0]
        r0 = np.concatenate([r0] + [t(T0) for t in self.terms], 1)
        c0 = robust_cost(r0, 3.0, self.coarse_w)
        order = np.argsort(c0)[:n]
        return st[[i for i in order if np.isfinite(c0[i])]]

    def best_ends_moved(self, x: np.ndarray, cost: np.ndarray) -> float:
        """How far (px) the cheapest row's end pixels lie from the first hypothesis searched
        (:func:`~.fit_starts.ends_moved`; 0 when no row is finite)."""
        if not np.isfinite(cost).any():
            return 0.0
        cam, model = self.fitter.stereo.left, self.fitter.model
        T = params_to_pose(x[[int(np.argmin(cost))]], cam, model)[0]
        return ends_moved(np.asarray(end_pixels(cam, T, model)), [self.tried[0]])
