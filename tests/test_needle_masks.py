"""The mask stage: coarse network masks refined to the needle's pixels, the gate width and
depth hint from the stereo pair, occluders marked."""

import numpy as np
from perception_helpers import stereo

from suture_bt.geometry import NeedleModel
from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.needle_masks import NeedleMasks


def _masks(**kw) -> NeedleMasks:
    """The mask stage at 1080p; coarse probabilities of 1 everywhere stand for a network that
    marks every pixel as needle."""
    return NeedleMasks(stereo(1920, 1080), NeedleModel(), ColourRule(), **kw)


def test_keypoint_depth_contradicted_by_the_masks_neither_gates_nor_hints():
    """A keypoint depth far too deep (0.3 m for a wire at 0.1 m) would gate the mask thinner
    than the wire and drop it all; the masks' own stereo disparity overrides it."""
    masks = _masks()
    left = np.zeros((1080, 1920, 3), np.uint8)
    right = left.copy()
    d = masks.stereo.left.fx * masks.stereo.baseline / 0.1  # 31.6 px at 0.1 m
    left[500:506, 900:1000] = (160, 160, 168)  # a wire 6 px wide: 0.72 mm at 0.1 m
    right[500:506, 900 - round(d) : 1000 - round(d)] = (160, 160, 168)
    prob = np.ones((2, 270, 480), np.float32)
    views, half_width, depth, _ = masks((left, right), prob, 4.0, 0.3)
    assert views[0].mask.sum() == 600 and views[1].mask.sum() == 600
    assert depth is None and half_width > 3.0
    # Agreeing depths are kept as the fit's hint.
    _, _, depth, _ = masks((left, right), prob, 4.0, 0.105)
    assert depth == 0.105


def test_masks_mark_the_occluder_and_keep_it_with_the_free_space_term():
    """A grey jaw touching the wire is marked as occluder in both modes (its boundary with
    the needle is no outline), and the free-space term does not discard that mark."""
    for free in (False, True):
        masks = _masks(use_free_space=free)
        d = round(masks.stereo.left.fx * masks.stereo.baseline / 0.1)  # disparity at 0.1 m
        images = []
        for shift in (0, d):
            img = np.zeros((1080, 1920, 3), np.uint8)
            img[:] = (215, 140, 132)
            img[500:506, 900 - shift : 1000 - shift] = (160, 160, 168)  # the wire
            img[480:526, 1000 - shift : 1040 - shift] = (190, 190, 196)  # a thick jaw at its end
            images.append(img)
        prob = np.ones((2, 270, 480), np.float32)
        views, _, _, _ = masks(tuple(images), prob, 4.0, 0.1)
        v = views[0]
        assert v.occluder is not None and v.occluder.any()
        assert not (v.occluder & v.mask).any()
        assert (v.free_dt is not None) == free
