"""A needle whose seen end meets the tissue may go on into it: the answer is refused when the
image and the priors let it slide along its circle that way, and kept when something pins it
(its other end seen, a held place)."""

import numpy as np
import pytest
from perception_helpers import MODEL, PINK, face_on_scene

from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.exposure_gate import ExposureGate
from suture_bt.perception.needle_prior import HeldPrior
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.tissue_slide import (
    MAX_TISSUE_SLIDE_DEG,
    TissueSlide,
    check_tissue_slide,
    tissue_slide,
)


def _seen_end(st, T) -> float:
    """The arc angle of the needle's left end in the left eye (``face_on_scene``'s jaw covers the
    right half)."""
    T_world = st.left.T_world_cam @ T
    ends = {MODEL.tip_angle: MODEL.tip, MODEL.base_angle: MODEL.base}
    u = {
        a: st.left.project((T_world[:3, :3] @ p + T_world[:3, 3])[None])[0, 0]
        for a, p in ends.items()
    }
    return min(u, key=u.get)


def _tissue_past(st, T, angle: float):
    """``inside_tissue`` of a flat tissue whose surface passes through the needle's end at
    ``angle``, across the arc: the arc continued past that end goes into it."""
    T_world = st.left.T_world_cam @ T
    at = T_world[:3, :3] @ MODEL.point_at(angle) + T_world[:3, 3]
    inward = T_world[:3, :3] @ MODEL.tangent_at(angle)  # towards the tip (decreasing angle)
    out = inward if angle == MODEL.tip_angle else -inward

    def inside(world, margin: float = 0.0):
        return (np.asarray(world, float).reshape(-1, 3) - at) @ out > margin

    return inside


def _slide(occluder: bool, priors=()):
    st, T, images, views = face_on_scene(occluder=occluder, background=PINK)
    gate = ExposureGate(st, MODEL, ColourRule(), tissue=_tissue_past(st, T, _seen_end(st, T)))
    return tissue_slide(gate, images, views, T, priors)


def test_a_needle_between_a_jaw_and_the_tissue_may_slide_into_the_tissue():
    slide = _slide(occluder=True)
    assert slide.worst > 20.0  # half the arc is under the jaw
    with pytest.raises(NeedleNotFound, match=r"meets the tissue .* slid up to \d+°"):
        check_tissue_slide(slide)


def test_a_needle_whose_other_end_is_seen_is_pinned():
    assert _slide(occluder=False).worst <= 2.0  # one sample: a mask's ragged end
    check_tissue_slide(_slide(occluder=False))


def test_a_held_place_pins_the_slide():
    st, T, _, _ = face_on_scene(occluder=True, background=PINK)
    T_world = st.left.T_world_cam @ T
    middle = 0.5 * (MODEL.tip_angle + MODEL.base_angle)
    pinch = T_world[:3, :3] @ MODEL.point_at(middle) + T_world[:3, 3]
    held = HeldPrior("psm2", pinch, 0.001, arc_angle=middle, arc_tolerance=0.0005)
    assert _slide(occluder=True, priors=(held,)).worst < MAX_TISSUE_SLIDE_DEG  # 0.5 mm: 2.8°


def test_no_tissue_known_means_no_slide():
    st, T, images, views = face_on_scene(occluder=True, background=PINK)
    slide = tissue_slide(ExposureGate(st, MODEL, ColourRule()), images, views, T)
    assert slide == TissueSlide()
    check_tissue_slide(TissueSlide(40.0, 0.0), limit_deg=float("inf"))
