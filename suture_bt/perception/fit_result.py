"""What the pose fit returns: the answer, its evidence and the ambiguity it measured."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PoseFitResult:
    """A fitted needle pose with its evidence.

    ``rms_px`` is the RMS edge residual of inliers; ``inlier_fraction`` the share of edge points
    within 1.5 px of the model outline; ``ambiguity`` the cost of the best clearly different
    solution minus the chosen one's (small: tilt-mirror not resolved); ``angle_std_deg`` and
    ``position_std_mm`` how loosely the seen outline pins the pose (:func:`pose_uncertainty`).
    """

    T_cam_needle: np.ndarray
    T_world_needle: np.ndarray
    params: np.ndarray
    cost: float
    rms_px: float
    inlier_fraction: float
    n_edge_points: tuple[int, int]
    ambiguity: float
    candidates: list = field(default_factory=list, repr=False)
    #: The polished candidates' costs (inf: outside the working range), as ``candidates``.
    candidate_costs: tuple[float, ...] = ()
    angle_std_deg: float = float("nan")
    position_std_mm: float = float("nan")
    #: The chosen pose's miss of each prior given, over its tolerance (≤ 1; empty: none).
    prior_misses: tuple[float, ...] = ()
    #: Cost of the cheapest clearly different pose (:mod:`rival_probe`) over the answer's
    #: (inf: none found), and its offset from the answer (mm, deg).
    rival_ratio: float = float("inf")
    rival_offset: tuple[float, float] | None = None
    #: Cost of the cheapest other candidate (a final pose or a probe's) clearly different from
    #: the answer and its base ↔ tip swap and usable under the priors, over the answer's (inf:
    #: none): near 1, a tie the image cannot break (:data:`~.rival_probe.MAX_TIE_RATIO`).
    tie_ratio: float = float("inf")
    #: Cost of the cheapest pose at least :data:`~.valley_probe.VALLEY_DEG` from the answer
    #: over the answer's (:mod:`valley_probe`; inf: none found or not probed), and its angle
    #: from the answer (deg).
    valley_ratio: float = float("inf")
    valley_deg: float = float("nan")
    #: How far (px) the answer's end pixels in the left image lie from the nearest end
    #: hypothesis the search started from, its second search's included
    #: (:func:`~.fit_starts.ends_moved`): far, and the hypotheses were wrong, so the search may
    #: have started in the wrong basin (:data:`~.fit_attempts.REFIT_MOVED_PX`).
    ends_moved_px: float = float("inf")
