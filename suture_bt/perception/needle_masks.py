"""The localiser's second stage: each eye's coarse network mask refined to the needle's
pixels at full resolution, with the gate width and depth hint the stereo pair measures.

The coarse blob at the trusted keypoints gates a colour test (:mod:`colour_refine`); the
masks' stereo disparity (:mod:`mask_disparity`) checks the keypoints' depth, the wire's own
thickness (:mod:`wire_width`) deciding when the two disagree; grey blobs thicker
than the widest plausible wire (jaws, shaft) are dropped, wire the coarse mask stopped short
of is added (:mod:`wire_growth`), band pieces a jaw cut off are added back
(:mod:`needle_ends`), occluder rims are dropped and occluders marked (:mod:`occlusion`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.base_or_tip import occlusion_radius
from suture_bt.perception.both_eyes import both_eyes
from suture_bt.perception.colour_refine import (
    ColourRule,
    coarse_components,
    drop_thick,
    free_space_dt,
    refine_mask,
)
from suture_bt.perception.mask_disparity import mask_disparity
from suture_bt.perception.mask_view import MaskView
from suture_bt.perception.needle_ends import with_band_pieces
from suture_bt.perception.occlusion import with_occluder, without_occluder_rims
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.wire_growth import grown_along_wire
from suture_bt.perception.wire_width import thin_for

#: Fewest full-resolution needle pixels per eye to attempt a fit.
MIN_NEEDLE_PIXELS = 15
#: Nearest needle distance considered (m): the working range's floor. The Task 3 start holds
#: the needle 27-50 mm from the left eye; a needle in a port is 47-93 mm away.
MIN_DEPTH = 0.02
#: The nearest distance (m) assumed where no stereo depth says otherwise: the widest wire, the
#: farthest apart two end keypoints or two mask pieces of one needle can be. Assuming the
#: working floor there instead let jaw pieces and jaw-tip keypoints pass as needle (two more
#: wrong answers on the development seed's occluded set).
NEAR_UNMEASURED = 0.05
#: Farthest plausible needle distance (m) for a disparity depth hint.
MAX_DEPTH = 0.35
#: Keypoint and mask stereo depths further apart than this (relative) disagree.
DEPTH_AGREEMENT = 0.3
#: Never treat a blob thinner than this (half width, px) as thicker than the wire.
MIN_HALF_WIDTH_PX = 1.5
#: Reach (in gate half-widths) within which a mask piece hugging an occluder counts as its rim
#: (:func:`~suture_bt.perception.occlusion.without_occluder_rims`): 3 px for a wire 7 px wide.
RIM_REACH = 0.6


@dataclass
class NeedleMasks:
    """Refines a stereo pair's coarse network masks (see the module docstring)."""

    stereo: StereoCameraModel
    model: NeedleModel
    rule: ColourRule
    #: Coarse probability over which a coarse pixel is needle.
    coarse_threshold: float = 0.3
    #: Whether to attach each view's free-space distance transform (the fit's experimental
    #: free-space term).
    use_free_space: bool = False
    #: Whether wire the coarse mask stopped short of is added (:mod:`wire_growth`).
    grow_wire: bool = True

    def __call__(self, images, prob, scale, depth, anchors=(None, None)):
        """Both eyes' refined needle masks, the depth hint for the fit, the gate (px) and the
        nearest the stereo depths let the needle be (m; None: no depth measured).

        Blobs touching the needle that are thicker than the widest plausible wire (jaws,
        shaft) are dropped. That width comes from the nearer of the keypoints' and the masks'
        stereo depths (a wrong depth must not make the gate thinner than the wire), else from
        the nearest working distance. A keypoint depth the masks contradict is not used as
        the fit's hint, unless the masks' wire is as thin as that depth says and far too thin
        for their own disparity (a blob in one eye dragged it); then the disparity is
        dropped. ``anchors`` are each eye's trusted end keypoints in coarse px (None: the
        largest coarse blob is the needle).
        """
        # Pieces of one needle lie within its chord of each other, at the nearest distance.
        chord = self.model.chord
        max_gap = chord * self.stereo.left.fx / NEAR_UNMEASURED / scale

        def raw_view(eye: int) -> MaskView:
            img, name = images[eye], ("left", "right")[eye]
            h = int(round(img.shape[0] / scale))
            coarse = coarse_components(
                prob[eye][:h], self.coarse_threshold, max_gap=max_gap, anchors=anchors[eye]
            )
            if coarse.sum() == 0:
                raise NeedleNotFound(
                    f"the network sees no needle in the {name} image", unseen_eye=name
                )
            return refine_mask(img, coarse, scale, self.rule)

        raw = both_eyes(raw_view)
        fx_left = self.stereo.left.fx
        fb = fx_left * self.stereo.baseline
        disp = mask_disparity(raw[0], raw[1], fb / MAX_DEPTH, fb / MIN_DEPTH)
        mask_depth = fb / disp if disp is not None and disp > 0 else None
        depths = [z for z in (depth, mask_depth) if z is not None]
        if depth is not None and mask_depth is not None:
            if abs(depth / mask_depth - 1.0) > DEPTH_AGREEMENT:
                masks = [v.mask for v in raw]
                if thin_for(masks, depth, mask_depth, self.model.wire_radius, fx_left):
                    # A blob of needle colour in one eye (a jaw's highlight) dragged the
                    # masks' disparity: the wire is as thin as the keypoints' depth says.
                    depths = [depth]
                else:
                    # Keypoints matched wrongly between the eyes (one on a jaw tip): the
                    # masks' depth stands alone.
                    depth = None
                    depths = [mask_depth]
        # The nearest the needle can be: the widest it can look.
        near = max(0.85 * min(depths), MIN_DEPTH) if depths else None
        z_near = NEAR_UNMEASURED if near is None else near
        half_width = 1.35 * self.model.wire_radius * self.stereo.left.fx / z_near
        half_width = max(half_width, MIN_HALF_WIDTH_PX)
        cams = (self.stereo.left, self.stereo.right)

        def gated_view(eye: int) -> MaskView:
            img, view = images[eye], drop_thick(raw[eye], half_width, self.rule)
            if self.grow_wire:
                reach = chord * cams[eye].fx / z_near
                view = grown_along_wire(img, view, half_width, reach, self.rule)
            view = with_band_pieces(
                img,
                view,
                chord * cams[eye].fx / z_near,
                z_near,
                cams[eye],
                self.model.wire_radius,
                self.rule,
            )
            if int(view.mask.sum()) < MIN_NEEDLE_PIXELS:
                raise NeedleNotFound(
                    f"too few needle-coloured pixels in the {('left', 'right')[eye]} image "
                    f"({int(view.mask.sum())} < {MIN_NEEDLE_PIXELS})"
                )
            view = without_occluder_rims(img, view, self.rule, round(RIM_REACH * half_width))
            view = with_occluder(img, view, self.rule, occlusion_radius(half_width))
            if self.use_free_space:
                dt, org = free_space_dt(img, view)
                view = replace(view, free_dt=dt, free_origin=org)
            return view

        return list(both_eyes(gated_view)), half_width, depth, near
