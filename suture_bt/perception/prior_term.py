"""The task's point priors as a soft term of the pose fit, and the information they add.

A held-by prior (the pinch point) and a port prior (the port) each say that a known point lies
on the needle's arc within a tolerance. Where the image pins the pose well this changes
nothing; where only a short piece of the needle is seen (a needle mostly inside the tissue and
the jaw) the image leaves the plane loose, and the two known points on the arc fix its depth and
turn; a held place (where along the needle the grasp holds it) fixes its slide along its own
circle, which nothing else does when both ends are hidden. The term pulls the polish towards
them (a robust loss: an image that contradicts a prior is not forced onto it, the prior gate
then refuses it), and :func:`prior_information` adds their information to the fit's predicted
spread.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_prior import HeldPrior, NeedlePrior, PortPrior, place_offsets

#: Pixels a miss of one tolerance counts as in the polish (about the spread of the edge
#: residuals there), so a prior weighs like an edge point as well placed as its tolerance says.
PRIOR_PX = 0.3
#: Edge points each of a prior's three components weighs in the polish (neighbouring edge
#: points are not independent, so one counts for less than its residual says). Development
#: task sets (seed 6173, with priors): 1 → 4 took held_presented from 0.36 to 0.30° and in a
#: port from 0.48 to 0.44° mean, the same answers right (without the term 0.42° and 0.51°).
PRIOR_WEIGHT = 4.0


class PriorTerm:
    """Residuals (K, 3·P + Q): each prior point's offset to the arc over its tolerance, then
    each held place's slide (a holder's pinch along the arc from where its grasp holds the
    needle, modulo the base ↔ tip swap) over its own, in PRIOR_PX per tolerance. Poses are
    left-camera ones, so points are taken to that frame."""

    polish = True

    def __init__(
        self, priors: Sequence[NeedlePrior], T_cam_world: np.ndarray, model: NeedleModel
    ) -> None:
        pts, tol, places = [], [], []
        for p in priors:
            if isinstance(p, HeldPrior | PortPrior):
                point = p.pinch_point if isinstance(p, HeldPrior) else p.point
                pts.append(T_cam_world[:3, :3] @ np.asarray(point, float) + T_cam_world[:3, 3])
                tol.append(p.tolerance)
            if isinstance(p, HeldPrior) and p.arc_angle is not None:
                places.append((len(pts) - 1, float(p.arc_angle), p.arc_tolerance))
        self.points = np.ascontiguousarray(np.array(pts, dtype=np.float64).reshape(-1, 3))
        self.tolerance = np.array(tol)
        #: Held places: (index of the pinch point, arc angle, tolerance along the arc).
        self.places = places
        self.model = model
        self._ends = np.stack([model.tip, model.base]).astype(np.float64)

    def __bool__(self) -> bool:
        return len(self.points) > 0

    def misses(self, T: np.ndarray) -> np.ndarray:
        """Offsets (K, P, 3) over each prior's tolerance (:func:`needle_prior.arc_offsets`,
        compiled: the fit calls this on small batches many times)."""
        m = self.model
        T = np.ascontiguousarray(T, dtype=np.float64)
        off = _arc_offsets(T, self.points, m.radius, m.tip_angle, m.base_angle, self._ends)
        return off / self.tolerance[None, :, None]

    def slides(self, T: np.ndarray) -> np.ndarray:
        """Each held place's signed slide (K, Q) over its tolerance: the pinch point's angle
        on the pose's circle from the held place, or from its swap's if that is nearer."""
        out = np.zeros((len(T), len(self.places)))
        for j, (i, a, tol) in enumerate(self.places):
            d = place_offsets(T, self.points[i], a, self.model)
            out[:, j] = d * self.model.radius / tol
        return out

    def scaled(self, T: np.ndarray) -> np.ndarray:
        """Every residual (K, 3·P + Q) in tolerances: the points' offsets, then the slides."""
        return np.concatenate([self.misses(T).reshape(len(T), -1), self.slides(T)], axis=1)

    def __call__(self, T: np.ndarray) -> np.ndarray:
        return PRIOR_PX * self.scaled(T)

    def column_weights(self, n_edge: int) -> np.ndarray:
        return np.full(3 * len(self.points) + len(self.places), PRIOR_WEIGHT)


class HeldPlaceTerm(PriorTerm):
    """The held places' slides alone, for the search before the polish: a needle whose ends
    are both hidden slides along its circle at no cost to the image, so the search's poses
    would stay wherever they start; this draws them to where the grasp holds the needle
    (the polish then weighs every prior, :class:`PriorTerm`)."""

    polish = False

    def __bool__(self) -> bool:
        return len(self.places) > 0

    def scaled(self, T: np.ndarray) -> np.ndarray:
        return self.slides(T)

    def column_weights(self, n_edge: int) -> np.ndarray:
        return np.full(len(self.places), PRIOR_WEIGHT)


@njit(cache=True)
def _arc_offsets(T, points, radius, tip_angle, base_angle, ends):
    """:func:`needle_prior.arc_offsets` per pose and point in one compiled loop: the vector
    (pose frame) from each point to the nearest point of the arc (on the circle within the
    span, else the nearer end; ``ends`` = tip, base in the needle frame)."""
    K, P = T.shape[0], points.shape[0]
    out = np.empty((K, P, 3))
    for k in range(K):
        for q in range(P):
            d0 = points[q, 0] - T[k, 0, 3]
            d1 = points[q, 1] - T[k, 1, 3]
            d2 = points[q, 2] - T[k, 2, 3]
            # the point in the needle frame: Rᵀ (point - t)
            p0 = T[k, 0, 0] * d0 + T[k, 1, 0] * d1 + T[k, 2, 0] * d2
            p1 = T[k, 0, 1] * d0 + T[k, 1, 1] * d1 + T[k, 2, 1] * d2
            p2 = T[k, 0, 2] * d0 + T[k, 1, 2] * d1 + T[k, 2, 2] * d2
            theta = math.atan2(p1, p0)
            if tip_angle <= theta <= base_angle:
                n0, n1, n2 = radius * math.cos(theta), radius * math.sin(theta), 0.0
            else:
                e = 0
                dt = (p0 - ends[0, 0]) ** 2 + (p1 - ends[0, 1]) ** 2 + (p2 - ends[0, 2]) ** 2
                db = (p0 - ends[1, 0]) ** 2 + (p1 - ends[1, 1]) ** 2 + (p2 - ends[1, 2]) ** 2
                if db < dt:
                    e = 1
                n0, n1, n2 = ends[e, 0], ends[e, 1], ends[e, 2]
            v0, v1, v2 = n0 - p0, n1 - p1, n2 - p2
            for i in range(3):
                out[k, q, i] = T[k, i, 0] * v0 + T[k, i, 1] * v1 + T[k, i, 2] * v2
    return out


def prior_information(term: PriorTerm | None, T: np.ndarray, T6: np.ndarray, steps) -> np.ndarray:
    """Information (6, 6) the priors add on the fit's parameters at pose T (4, 4), from the
    poses T6 (6, 4, 4) stepped by ``steps`` in each parameter: Jᵀ J of the misses in
    tolerances (each prior taken at its stated tolerance, as a Gaussian)."""
    if not term:
        return np.zeros((6, 6))
    m0 = term.scaled(T[None]).reshape(-1)
    J = (term.scaled(T6).reshape(6, -1) - m0[None]) / np.asarray(steps)[:, None]
    return J @ J.T
