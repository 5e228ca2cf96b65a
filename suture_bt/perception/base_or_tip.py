"""Which fitted end is the needle's base: the outline is the same for a pose and its 180° base
↔ tip swap, so the violet swage band at the base decides by colour (:mod:`needle_ends`), else
continuity with a previous estimate, else the face a holder's jaws hold it by; with none of
these the localiser refuses rather than guess (a swapped needle sends the grasp and the
insertion to the wrong end)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.mask_view import MaskView
from suture_bt.perception.needle_ends import (
    BAND_LENGTH,
    MIN_EVIDENCE,
    band_miss_px,
    band_offset,
    base_evidence,
)
from suture_bt.perception.occlusion import end_is_occluded
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.transforms import rotation_angle

#: A fitted end whose pixel is farther than this from the needle mask is not seen: the fit put
#: it behind something, and the grey wire leading up to it says nothing about which end it is.
END_ON_MASK_PX = 2.0
#: How far past a fitted end (m, along the circle) the wire is looked for inside the tissue,
#: and how deep inside it must be there (m) for the end to count as cut by the tissue.
CUT_PROBE, CUT_DEPTH = 0.002, 0.0003
#: Farthest the seen swage band may start from the fitted base (m, along the arc): half a band
#: length of slack past the band's own 3 mm.
MAX_BAND_OFFSET = 1.5 * BAND_LENGTH
#: Farthest the seen swage band may lie off the fitted arc, in the wire's half widths (px):
#: on the development frames (seeds 1000 and 6173, 493 answers with the band seen) every right
#: answer had it within 0.72 of them (p99 0.55, median 0.35). Found on a report seed's wrong
#: answer (a handover needle 10° off whose base swung 23 px past the band a jaw cut off).
MAX_BAND_MISS = 1.5
#: How far (wire half widths) from the fitted band's projection violet pixels are looked for.
BAND_REACH = 8.0


def occlusion_radius(half_width: float) -> float:
    """How far (px) around an end pixel an occluder is looked for: the wire's width and a bit."""
    return 2.0 * half_width + 3.0


def on_mask(view: MaskView, uv: np.ndarray, tol_px: float) -> bool:
    """Whether a needle-mask pixel lies within ``tol_px`` of the full-image pixel ``uv``."""
    x0, y0 = view.origin
    u, v = float(uv[0]) - x0, float(uv[1]) - y0
    r = int(np.ceil(tol_px))
    h, w = view.mask.shape
    a, b = max(int(np.floor(u)) - r, 0), min(int(np.floor(u)) + r + 2, w)
    c, d = max(int(np.floor(v)) - r, 0), min(int(np.floor(v)) + r + 2, h)
    if a >= b or c >= d:
        return False
    yy, xx = np.nonzero(view.mask[c:d, a:b])
    return bool(np.any((xx + a - u) ** 2 + (yy + c - v) ** 2 <= tol_px**2))


@dataclass
class BaseTipChooser:
    """Chooses between a fitted pose and its base ↔ tip swap for a localiser: its cameras,
    needle model, colour rule and (optional) tissue model (:mod:`unseen_arc`)."""

    stereo: StereoCameraModel
    model: NeedleModel
    rule: ColourRule
    tissue: Callable[..., np.ndarray] | None = None

    def ends_in_tissue(self, T_cam: np.ndarray) -> tuple[bool, bool]:
        """(base, tip): whether the circle continued CUT_PROBE past that fitted end runs into
        the known tissue (a needle in a port: the wire may go on inside, and the grey where
        the fit ends it is not its tip). (False, False) without a tissue model."""
        if self.tissue is None:
            return False, False
        m, T = self.model, self.stereo.left.T_world_cam @ T_cam
        step = CUT_PROBE / m.radius
        past = m.point_at(np.array([m.base_angle + step, m.tip_angle - step]))
        world = past @ T[:3, :3].T + T[:3, 3]
        inside = self.tissue(world, margin=CUT_DEPTH)
        return bool(inside[0]), bool(inside[1])

    def orient(self, T_cam: np.ndarray, images, views, half_width: float, previous, jaws=()):
        """(pose, colour evidence, what decided): the swage band's colour, else continuity
        with ``previous``, else the holder's jaws (``jaws``: ``AcrossJawsPrior``, the needle's
        face as held); with none, NeedleNotFound.

        A fitted end that touches an occluder may hide the band, and one off the mask is not
        seen at all: the grey there does not vote.
        (The network's base keypoint used to decide when the band did not: over the 600 scenes
        of the 1080p benchmark sets it was right for 4 of the 12 needles it decided.)
        """
        radius = occlusion_radius(half_width)

        def end_hidden(eye: int, uv: np.ndarray) -> bool:
            return not on_mask(views[eye], uv, END_ON_MASK_PX) or end_is_occluded(
                images[eye], views[eye], uv, radius, self.rule
            )

        cams = (self.stereo.left, self.stereo.right)
        evidence = base_evidence(
            images,
            tuple(views),
            cams,
            T_cam,
            self.model,
            end_hidden=end_hidden,
            ends_cut=self.ends_in_tissue(T_cam),
        )
        if abs(evidence) >= MIN_EVIDENCE:
            T_cam = T_cam if evidence > 0 else self.model.swapped(T_cam)
            offset = band_offset(images, tuple(views), cams, T_cam, self.model)
            if offset is not None and offset > MAX_BAND_OFFSET:
                raise NeedleNotFound(
                    f"the swage band starts {1e3 * offset:.1f} mm from the fitted base (it "
                    f"covers the first {1e3 * BAND_LENGTH:.0f} mm): the fit slid along the "
                    "needle's circle"
                )
            reach = BAND_REACH * half_width
            miss = band_miss_px(tuple(images), cams, T_cam, self.model, reach)
            if miss is not None and miss > MAX_BAND_MISS * half_width:
                raise NeedleNotFound(
                    f"the swage band lies {miss:.1f} px off the fitted arc (limit "
                    f"{MAX_BAND_MISS * half_width:.1f} px, {MAX_BAND_MISS:g} wire half widths): "
                    "the fit explains the seen piece but swings away from the needle's base"
                )
            return T_cam, evidence, "colour"
        if previous is not None:
            other = self.model.swapped(T_cam)
            prev = np.asarray(previous, float)[:3, :3]
            keep = rotation_angle(prev, T_cam[:3, :3]) <= rotation_angle(prev, other[:3, :3])
            return (T_cam if keep else other), evidence, "previous"
        if jaws:
            other = self.model.swapped(T_cam)
            to_world = self.stereo.left.T_world_cam
            keep = jaws[0].facing(to_world @ T_cam, to_world @ other)
            return (T_cam if keep else other), evidence, "jaws"
        raise NeedleNotFound(
            "which end is the base cannot be told: the swage band shows at neither fitted end "
            f"(colour evidence {evidence:+.2f}, needs ±{MIN_EVIDENCE:.2f}) and there is no "
            "previous estimate to follow"
        )
