"""Stereo needle-pose fit: the seed's parameterisation, an unbiased edge objective, batched LM.

Objective (one-sided, mask → model, so occluded parts of the needle cost nothing): every mask
edge point (midpoint between a needle pixel and a 4-neighbour background pixel) back-projects
to a ray that should be tangent to the wire. The wire is the union of spheres of the wire
radius along the centre-line arc, so a ray is tangent exactly when its distance to the arc is
the wire radius; the residual is that distance minus the radius, in pixels at the point's
depth. Rays past either end measure to the end point, which is the hemispherical cap. Unlike a
chamfer to the centre-line this has no pull along the line of sight (DESIGN.md §5).
Minimised by Levenberg-Marquardt with robust weights, vectorised over many starts (the
tilt-mirror ambiguity), on the parameters of :mod:`needle_projection`: Cauchy while searching
(wide basins), Geman-McClure for the final polish and choice, so a few stray mask pixels (a
sliver of jaw the colour test kept) cannot pull the answer onto a pose that half-explains them.
Optional extra terms: free space (experimental, off) and confident keypoints (search only).
The answer is then probed for a cheaper pose (its depth-mirror twin, slides along its circle,
small turns) and for a clearly different pose of near-equal cost (:mod:`rival_probe`).
The starts are :mod:`fit_search`'s, the answer's evidence :mod:`fit_answer`'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.answer_probes import probed
from suture_bt.perception.edge_residuals import (  # noqa: F401 - re-exported
    N_THETA_GRID,
    EdgeRays,
    _arc_f,
    _to_needle,
    edge_jacobian,
    edge_rays,
    nearest_arc_angle,
    residuals,
)
from suture_bt.perception.edge_samples import mask_ends  # noqa: F401 - re-exported
from suture_bt.perception.fit_answer import answer_result
from suture_bt.perception.fit_result import PoseFitResult
from suture_bt.perception.fit_search import StartSearch
from suture_bt.perception.fit_solver import (  # noqa: F401 - re-exported
    FD_STEPS,
    levenberg_marquardt,
    pose_uncertainty,
)
from suture_bt.perception.fit_starts import (
    DISTINCT,
    diverse,
    rot_angle,
    start_params,
)
from suture_bt.perception.fit_terms import (  # noqa: F401 - re-exported
    END_PRIOR_SHARE,
    EndPriorTerm,
    FreeSpaceTerm,
)
from suture_bt.perception.mask_view import MaskView, edge_points  # noqa: F401 - re-exported
from suture_bt.perception.needle_prior import (
    NeedlePrior,
    choose_answer,
    port_planes,
    with_consistent,
)
from suture_bt.perception.needle_projection import (
    end_pixels,
    params_to_pose,
)
from suture_bt.perception.prior_term import PriorTerm
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.rival_probe import FitRays
from suture_bt.perception.robust_cost import LOSSES, robust_cost  # noqa: F401 - re-exported
from suture_bt.perception.tissue_cut import TissueCut

#: A clearly different second-stage pose costing at most this much more than the best also
#: seeds the second search (1.3 gave the same answers on the benchmarks for 10 ms more).
RESEED_RIVAL_RATIO = 1.1
#: The search is repeated from the best pose's own ends (``n_reseed``) also when no end is
#: thought hidden but those ends lie farther than this (px) from the first hypothesis's (the
#: keypoints): one keypoint sat elsewhere on the wire, and the best pose grew from another
#: hypothesis's start without the fresh grid of plane angles at its own ends. Session 39's one
#: wrong SRC answer (report seed 54059973, ``unoccluded`` #52: a free needle seen nearly
#: end-on 139 mm away, one keypoint on the arc's bulge 36 px from either end, answered
#: 1.22 mm / 167.7 deg off: 13.8 deg after the base-tip swap, at 1.7x the cost of the truth
#: polished) is then answered 0.31 mm / 0.12 deg off; of the other 645 cached development
#: calls it changes none by more than 1e-6 mm or deg.
RESEED_MOVED_PX = 8.0


@dataclass
class PoseFitter:
    """Multi-start stereo fit of the needle pose to two masks (see module docstring)."""

    stereo: StereoCameraModel
    model: NeedleModel = field(default_factory=NeedleModel)
    n_psi: int = 12
    max_points_per_eye: int = 1200
    coarse_points_per_eye: int = 40
    mid_points_per_eye: int = 200
    n_keep: int = 12
    n_keep_alternative: int = 6
    #: Starts kept of the wire entering the known tissue (:mod:`entry_starts`: 5 seen arcs,
    #: 2 depths, 12 turns about the chord). A short seen piece is almost straight, so the
    #: coarse cost hardly tells the turns apart: with 6 kept, held-out report 78041143
    #: `in_port` #29 without priors (session 41) lost the true turn and was answered 19 mm /
    #: 148° off, with 9, 12, 18 or 24 it is answered 0.12 mm / 0.7° off. 12, as many as the main
    #: hypothesis keeps: on 921 cached development calls the same verdicts but that one and a
    #: refusal now answered right; 8 other answers moved, none by more than 0.001° worse;
    #: no time measurable (two interleaved runs of each: 1 ms faster, within the noise).
    n_keep_entry: int = 12
    min_edge_points: int = 12
    seed: int = 0
    #: LM iterations: all kept starts at σ = 3 px on the coarse subsample, the best
    #: ``n_second_stage`` (clearly different ones first, see ``_diverse``) at σ = 1 px on the
    #: mid one, then the best ``n_final`` clearly
    #: different solutions on every edge point. Many cheap first-stage starts find the right
    #: basin more often than few expensive ones (1080p occluded benchmark, cached scenes:
    #: success 0.465 -> 0.495 at 134 -> 119 ms with 12 + 6 starts and 8 second-stage ones).
    iterations: tuple[int, int, int] = (8, 8, 6)
    n_second_stage: int = 6
    #: Clearly different solutions (> DISTINCT apart) polished on every edge point.
    n_final: int = 2
    #: Starts of a second search from the best second-stage pose's own end pixels and depth
    #: (0: none), made when an end may be hidden (see ``fit``) or the best pose's ends lie
    #: over RESEED_MOVED_PX from the first hypothesis; as many again from a clearly different
    #: rival within RESEED_RIVAL_RATIO of its cost.
    #: 1080p occluded benchmark: success 0.690 -> 0.735 (seed 1000), 0.735 -> 0.785 (2000);
    #: the rival's seeds: 0.745 -> 0.750, 0.77 -> 0.70 mm, 9.6 -> 7.4 deg (seed 1000),
    #: 0.795 -> 0.800, 0.92 -> 0.89 mm (seed 2000), for about 3 ms; 12 instead of 6 starts
    #: (cached scenes, with the faster LM): 0.60 -> 0.49 mm, 6.1 -> 5.3 deg (seed 1000),
    #: success 0.850 -> 0.860, 0.63 -> 0.60 mm, 8.5 -> 8.1 deg (seed 2000), about 4 ms; 18:
    #: the same answers.
    n_reseed: int = 12
    #: Loss of that polish, whose cost also chooses between them (see LOSSES).
    final_loss: str = "geman_mcclure"
    #: Working distance (m) of the arc centre from the left camera: fits outside are rejected
    #: (a short visible piece is also explained by a much nearer, larger-looking needle).
    depth_range: tuple[float, float] = (0.03, 0.5)
    #: Whether the priors' points (pinch, port) join the polish as a soft term and the
    #: predicted spread (:mod:`prior_term`).
    prior_polish: bool = True
    #: Whether the answer is probed for clearly different poses of near-equal cost
    #: (:mod:`rival_probe`; a cheaper one becomes the answer).
    probe_rivals: bool = True
    #: Whether an answer with a hidden end (or given priors) is slid along its own circle in
    #: search of a cheaper pose (:mod:`rival_probe`, where its development figures are).
    probe_slides: bool = True
    #: Whether the answer is also turned by a few degrees in search of a cheaper basin next to
    #: it (:mod:`rival_probe`).
    probe_near: bool = True
    #: Whether the answer's depth-mirror twin with the same end pixels is also descended from
    #: (:func:`~rival_probe.twin_starts`; a cheaper result replaces the answer).
    probe_twin: bool = True
    #: Whether the probed answer is also descended again from the search's wide stage
    #: (:func:`~answer_probes.wide_redescent`; a cheaper result replaces the answer).
    probe_wide: bool = True
    #: Whether the answer's cheapest pose a few degrees away is sought (:mod:`valley_probe`;
    #: its cost ratio is a refusal gate, ``AnswerGates.max_valley_ratio``).
    probe_valley: bool = True
    #: The task's known tissue solid as convex pieces of world (point, outward normal) planes
    #: (:func:`~suture_bt.geometry.tissue_surface.solid_pieces`; None: unknown): the arc
    #: inside it is hidden, and the seen wire ends where it enters (:mod:`tissue_cut`).
    tissue_solid: Sequence | None = None
    #: How deep (m) an arc must reach into the known solid for the solid to hide it: a pose
    #: that only dips under the surface is seen whole (not so for the ports' planes).
    solid_depth: float = 0.001

    def fit(
        self,
        left: MaskView,
        right: MaskView,
        endpoints_left: tuple[np.ndarray, np.ndarray] | None = None,
        depth_hint: float | None = None,
        warm_start: np.ndarray | None = None,
        alternatives: Sequence[tuple[np.ndarray, np.ndarray] | None] = (),
        end_priors: tuple[np.ndarray, np.ndarray] | None = None,
        hidden_end: bool | None = None,
        priors: Sequence[NeedlePrior] = (),
        seeds: np.ndarray | None = None,
    ) -> PoseFitResult:
        """Fit; ``endpoints_left`` = (base uv, tip uv) in the left image; raise NeedleNotFound.

        ``seeds`` (K, 4, 4: left-camera poses, e.g. :func:`~prior_seeds.seed_poses` of the
        priors) are further starts, the ``n_keep`` cheapest of them searched with the rest.

        ``end_priors`` (left, right pixel arrays) are keypoints the network is sure of: each
        pulls the nearer model end towards it (:class:`EndPriorTerm`). ``hidden_end`` says
        whether an end may be hidden (then the search is repeated from the best pose's own
        ends, ``n_reseed``, as it also is when those ends lie over RESEED_MOVED_PX from the
        first hypothesis); None: whenever there are ``alternatives``.

        ``alternatives`` are further end-pixel hypotheses (``None``: the mask's own farthest
        pair), searched over all depths; the best ``n_keep_alternative`` starts of each join
        the main hypothesis' in one batched fit, so a wrong keypoint or a hidden end costs one
        fit, not several.

        ``priors`` (:mod:`needle_prior`: held by an arm, in a port, a predicted pose) choose
        among the final candidates: the second search from the best pose's own ends always runs
        (it reaches the mirror twin), the best consistent second-stage pose joins the polish,
        and the answer is the best-cost consistent polished pose; none consistent (or none
        within MAX_PRIOR_COST_RATIO of the cheapest) raises :class:`PriorContradicted` naming
        the prior. Ports given with their surface normals hide the arc below them, and the
        known tissue solid (``tissue_solid``) the arc inside it: the edge rays measure to its
        seen part (:mod:`tissue_cut`), and the search also starts from the wire entering the
        tissue at an end of the outline (:mod:`entry_starts`).
        """
        search = StartSearch.begin(self, left, right, end_priors, priors)
        rays, coarse, mid, terms = search.rays, search.coarse, search.mid, search.terms
        cam = self.stereo.left
        if endpoints_left is None and warm_start is not None:
            endpoints_left = tuple(end_pixels(cam, np.asarray(warm_start), self.model))
        starts = search.first_starts(endpoints_left, depth_hint, warm_start, alternatives, seeds)
        it1, it2, it3 = self.iterations
        x, c1 = levenberg_marquardt(starts, coarse, self.stereo, self.model, it1, 3.0, terms)
        if self.n_second_stage and len(x) > self.n_second_stage:
            x = x[self._diverse(x, c1, self.n_second_stage)]
        x, c = levenberg_marquardt(x, mid, self.stereo, self.model, it2, 1.0, terms)
        c = np.where(self.in_range(x), c, np.inf)
        if hidden_end is None:
            hidden_end = bool(alternatives)
        hidden_end = hidden_end or bool(priors)
        # The first hypothesis's ends (the keypoints) far from the best pose's: one of them sat
        # elsewhere on the wire, and the best pose came from another hypothesis's start.
        led_away = (
            not hidden_end and bool(search.tried) and search.best_ends_moved(x, c) > RESEED_MOVED_PX
        )
        if self.n_reseed and (hidden_end or led_away) and np.isfinite(c).any():
            # The best pose's own end pixels and depth are sharper than any keypoint: a fresh
            # grid of plane angles there reaches the tilt-mirror twin the first starts missed.
            # A close rival's ends may be the right ones: it seeds the search too.
            st = search.reseed_starts(x, c, RESEED_RIVAL_RATIO)
            if len(st):
                y, cy = levenberg_marquardt(st, coarse, self.stereo, self.model, it1, 3.0, terms)
                y, cy = levenberg_marquardt(y, mid, self.stereo, self.model, it2, 1.0, terms)
                x = np.concatenate([x, y])
                c = np.concatenate([c, np.where(self.in_range(y), cy, np.inf)])
        if not np.isfinite(c).any():
            lo, hi = self.depth_range
            raise NeedleNotFound(
                f"no pose {1e3 * lo:.0f}-{1e3 * hi:.0f} mm from the camera explains the outline"
            )
        order = np.argsort(c)
        T_mid = params_to_pose(x[order], cam, self.model)
        finals, kept = [order[0]], [0]
        for j, k in enumerate(order[1:], 1):
            if len(finals) == self.n_final or not np.isfinite(c[k]):
                break
            if all(rot_angle(T_mid[i, :3, :3], T_mid[j, :3, :3]) > DISTINCT for i in kept):
                finals.append(k)
                kept.append(j)
        if priors:
            finals = with_consistent(finals, self.world_poses(x), c, priors, self.model)
        polish = [t for t in terms if t.polish]
        prior_term = PriorTerm(priors, cam.T_cam_world, self.model) if self.prior_polish else None
        if prior_term:
            polish.append(prior_term)
        xf, cf = levenberg_marquardt(
            x[finals], rays, self.stereo, self.model, it3, 1.0, polish, self.final_loss
        )
        cf = np.where(self.in_range(xf), cf, np.inf)
        if not np.isfinite(cf).any():
            raise NeedleNotFound("pose fit diverged")
        b, ok, misses = choose_answer(self.world_poses(xf), cf, priors, self.model)
        amb = float(np.min(np.delete(cf, b)) - cf[b]) if len(cf) > 1 else float("inf")
        xf, cf, b, ok, misses, near = probed(
            self, xf, cf, (b, ok, misses), FitRays(rays, coarse, mid), polish, priors, hidden_end
        )
        return answer_result(search, xf, cf, (b, ok, misses, near), polish, amb)

    def tissue_cut(self, priors: Sequence[NeedlePrior] = ()) -> TissueCut:
        """Where the tissue hides the arc for a fit with these priors: the known solid (if
        given) and the port priors' planes; what the final answer's edge rays measure to."""
        ports = port_planes(priors)
        if self.tissue_solid:
            return self._with_solid(ports)
        return TissueCut.from_ports(ports, self.stereo.left.T_cam_world, self.model)

    def _with_solid(self, ports) -> TissueCut:
        """The cut of the port priors' planes (depth 0) and the known solid's pieces (each
        ``solid_depth`` deep)."""
        solid = list(self.tissue_solid)
        pieces = ([ports] if ports else []) + solid
        depths = [0.0] * (len(pieces) - len(solid)) + [self.solid_depth] * len(solid)
        return TissueCut.from_pieces(pieces, self.stereo.left.T_cam_world, self.model, depths)

    def world_poses(self, x: np.ndarray) -> np.ndarray:
        """World poses (K, 4, 4) of parameter rows (priors are in the world frame)."""
        cam = self.stereo.left
        return cam.T_world_cam[None] @ params_to_pose(x, cam, self.model)

    def _diverse(self, x: np.ndarray, cost: np.ndarray, n: int) -> np.ndarray:
        """:func:`~.fit_starts.diverse` with this fitter's camera and model."""
        return diverse(x, cost, n, self.stereo.left, self.model)

    def in_range(self, x: np.ndarray) -> np.ndarray:
        """Which parameter rows put the arc centre within ``depth_range`` of the camera."""
        z = params_to_pose(x, self.stereo.left, self.model)[:, 2, 3]
        return (z >= self.depth_range[0]) & (z <= self.depth_range[1])

    def _starts(self, ub: np.ndarray, ut: np.ndarray, depth_hint: float | None) -> np.ndarray:
        """:func:`~.fit_starts.start_params` with this fitter's camera, model and psi count."""
        return start_params(ub, ut, depth_hint, self.stereo.left, self.model, self.n_psi)
