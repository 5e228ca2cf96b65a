"""The needle localiser's answer: a pose with the evidence behind it and per-stage timings."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from suture_bt.perception.mask_view import MaskView
from suture_bt.perception.pose_fit import PoseFitResult
from suture_bt.perception.unseen_arc import ArcExposure


@dataclass(frozen=True)
class NeedleEstimate:
    """The localiser's answer: pose (left camera and world), fit evidence and timings (ms)."""

    T_cam_needle: np.ndarray
    T_world_needle: np.ndarray
    rms_px: float
    inlier_fraction: float
    ambiguity: float
    keypoints_left: np.ndarray
    keypoint_scores: np.ndarray
    #: Colour vote for the base↔tip choice (> 0 kept, < 0 swapped) and what decided it:
    #: "colour" (the swage band), "previous" (the nearer of the two to the previous estimate)
    #: or "jaws" (the face a holder's jaws hold it by: :class:`AcrossJawsPrior`).
    end_evidence: float
    end_decided_by: str
    timings_ms: dict
    fit: PoseFitResult = field(repr=False)
    masks: tuple[MaskView, MaskView] = field(repr=False)
    #: The task priors the answer was checked against (:mod:`needle_prior`; empty: none).
    priors: tuple = ()
    #: Where the model arc lies unseen and unhidden, per eye (:mod:`unseen_arc`).
    exposure: ArcExposure | None = field(default=None, repr=False)
    #: Full-resolution px per px of ``masks``, ``keypoints_left`` and the fit's pixel figures
    #: (``rms_px``): 2 when a near needle was measured on the halved images (:mod:`near_view`).
    pixel_scale: float = 1.0

    @property
    def angle_std_deg(self) -> float:
        """Predicted angle spread of the pose (deg): how loosely the seen outline pins it."""
        return self.fit.angle_std_deg

    @property
    def position_std_mm(self) -> float:
        """Predicted spread of the arc centre (mm)."""
        return self.fit.position_std_mm

    @property
    def confidence(self) -> float:
        """0..1: share of edge points explained, discounted for large residuals."""
        return float(self.inlier_fraction / (1.0 + max(self.rms_px - 0.5, 0.0)))
