"""How far an answer could slide along its own circle into the tissue and show the same image.

A needle held in a jaw with its other end pushed into the tissue shows one piece of wire
between two hiders. Slid along its own circle it projects the same circle, so the piece is
explained as well, and the outline cannot say how deep the end goes: the fit puts an end cap
where the wire meets the tissue. That answered two Task 3 starts 14° and 18° off, their tips
2.6 and 4.4 mm of arc inside the tissue (report seeds 82330937 #68 and 57264705 #13,
``held_start`` with priors).

Where the answer's arc, continued past an end, enters the known tissue's solid, its circle is
sampled past that end and each sample classed as the exposure gate does
(:func:`~suture_bt.perception.unseen_arc.classify_points`: seen, hidden by a jaw, the border
or the tissue, or exposed). A slide that way is allowed while the slid arc keeps all the wire
either eye sees, runs over no more exposed pixels and still agrees with every prior (a held
pinch point stays on the arc, a port stays passed). An answer that may slide farther than
:data:`MAX_TISSUE_SLIDE_DEG` is not pinned by the image: refused with the reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from suture_bt.perception.exposure_gate import ExposureGate
from suture_bt.perception.mask_view import MaskView
from suture_bt.perception.needle_prior import NeedlePrior, consistent, prior_misses
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.rival_probe import slid_along_circle
from suture_bt.perception.unseen_arc import EXPOSED, N_SAMPLES, SEEN, classify_points

#: How far (deg) a slide is tried.
SLIDE_REACH_DEG = 30.0
#: Samples (about 2° each) a slid arc may leave of the seen wire's extent, or add of exposed
#: pixels, in an eye (a mask's ragged end).
SLACK_SAMPLES = 1
#: Samples past an end (about 0.35 mm each) looked at for the tissue's solid, and how deep
#: inside it (m) one must lie for the end to count as going into the tissue.
INTO_SAMPLES = 4
SOLID_MARGIN = 1e-4
#: An answer that may slide farther than this (deg) into the tissue is refused: it may be off
#: by as much, and 5° is the line of a wrong answer. On the 2,368 development calls (1,840
#: answers) one right answer slid farther (a needle behind the ridge, 31°), every other at
#: most one sample beyond its seen wire (2°); the two report answers above slide 8° and 27°.
MAX_TISSUE_SLIDE_DEG = 5.0


@dataclass(frozen=True)
class TissueSlide:
    """How far (deg) the answer may slide along its circle pushing its tip-side end (in the
    fitted frame, which may still have base and tip swapped) or its base-side end into the
    tissue; 0 where that end's continuation does not enter the tissue."""

    towards_tip: float = 0.0
    towards_base: float = 0.0

    @property
    def worst(self) -> float:
        """The farther of the two (deg)."""
        return max(self.towards_tip, self.towards_base)


def tissue_slide(
    gate: ExposureGate,
    images: tuple[np.ndarray, np.ndarray],
    views: tuple[MaskView, MaskView],
    T_cam: np.ndarray,
    priors: Sequence[NeedlePrior] = (),
) -> TissueSlide:
    """How far the pose ``T_cam`` (left-camera frame) may slide into the tissue each way,
    classed as ``gate`` classes the arc (its cameras, needle, colour rule and tissue; with no
    tissue known and no port in ``priors``, no slide is looked for)."""
    stereo, model = gate.stereo, gate.model
    inside_tissue, tissue_hides = gate.hiders(priors)
    if inside_tissue is None:
        return TissueSlide()
    step = (model.base_angle - model.tip_angle) / (N_SAMPLES - 1)
    n_ext = int(np.ceil(np.radians(SLIDE_REACH_DEG) / step))
    k = np.arange(-n_ext, N_SAMPLES + n_ext)
    T_world = stereo.left.T_world_cam @ np.asarray(T_cam, float)
    world = model.point_at(model.tip_angle + k * step) @ T_world[:3, :3].T + T_world[:3, 3]
    solid = np.asarray(inside_tissue(world, margin=SOLID_MARGIN))
    into = (
        bool(solid[n_ext - INTO_SAMPLES : n_ext].any()),
        bool(solid[n_ext + N_SAMPLES : n_ext + N_SAMPLES + INTO_SAMPLES].any()),
    )
    if not any(into):
        return TissueSlide()
    in_tissue = np.asarray(inside_tissue(world))
    classes = classify_points(
        images, views, stereo, world, in_tissue, gate.half_width(T_cam), gate.rule, tissue_hides
    )
    exposed = np.stack([np.cumsum(np.r_[0, c == EXPOSED]) for c in classes])
    exposed0 = exposed[:, n_ext + N_SAMPLES] - exposed[:, n_ext]
    # Samples from the answer's tip end to the first seen one and from the last seen one to
    # its base end, over both eyes (negative where the seen wire reaches past the answer): the
    # slid arc must still cover the seen wire.
    first, last = n_ext, n_ext
    for c in classes:
        idx = np.flatnonzero(c == SEEN) - n_ext
        if len(idx):
            first, last = min(first, idx[0]), min(last, N_SAMPLES - 1 - idx[-1])
    shifts = np.arange(1, n_ext + 1)
    reach = []
    for go, sign, room in zip(into, (-1, 1), (last, first), strict=True):
        if not go:
            reach.append(0.0)
            continue
        s = sign * shifts
        a, b = n_ext + s, n_ext + s + N_SAMPLES
        ok = (shifts <= room + SLACK_SAMPLES) & np.all(
            exposed[:, b] - exposed[:, a] <= exposed0[:, None] + SLACK_SAMPLES, axis=0
        )
        if priors:
            ok &= consistent(prior_misses(priors, slid_along_circle(T_world, s * step), model))
        n = int(np.argmin(ok)) if not ok.all() else len(ok)
        reach.append(float(np.degrees(n * step)))
    return TissueSlide(reach[0], reach[1])


def check_tissue_slide(slide: TissueSlide, limit_deg: float = MAX_TISSUE_SLIDE_DEG) -> None:
    """Refuse an answer that may slide farther than ``limit_deg`` into the tissue."""
    if slide.worst > limit_deg:
        raise NeedleNotFound(
            f"an end of the fitted arc meets the tissue and the needle may go on into it: slid "
            f"up to {slide.worst:.0f}° along its own circle (limit {limit_deg:.0f}°) it shows "
            "the same wire, hides the rest (a jaw, the tissue, the border) and agrees with the "
            "priors, so the seen piece does not pin where along its circle the needle lies"
        )
