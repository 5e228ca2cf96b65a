"""Colour refinement recovers the exact wire mask inside a coarse gate and drops thick blobs."""

import cv2
import numpy as np
from perception_helpers import stereo

from suture_bt.geometry import NeedleModel
from suture_bt.perception.colour_refine import (
    ColourRule,
    channel_sum,
    coarse_components,
    frame_exposure,
    needle_coloured,
    refine_mask,
    remove_thick,
    tissue_coloured,
    violet_score,
)
from suture_bt.perception.needle_projection import rasterize_needle


def _scene():
    cam = stereo(960, 540).left
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.09)
    wire = rasterize_needle(cam, T, NeedleModel())
    rng = np.random.default_rng(0)
    img = np.empty((540, 960, 3), np.float32)
    img[:] = (215, 140, 132)  # tissue pink
    img[wire] = (150, 152, 160)  # needle grey
    img += rng.normal(0, 4, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8), wire


def _full(view, shape):
    out = np.zeros(shape, bool)
    x0, y0 = view.origin
    out[y0 : y0 + view.mask.shape[0], x0 : x0 + view.mask.shape[1]] = view.mask
    return out


def test_refined_mask_matches_the_wire_exactly():
    img, wire = _scene()
    scale = 4.0
    small = cv2.resize(wire.astype(np.float32), (240, 135), interpolation=cv2.INTER_AREA)
    coarse = coarse_components(small * 2.0)  # a coarse "probability" of the wire
    view = refine_mask(img, coarse, scale)
    full = _full(view, wire.shape)
    assert (full != wire).sum() <= 2
    assert view.origin[0] > 0 and view.mask.shape[1] < 960


def test_grey_blob_outside_the_gate_is_ignored_and_thick_blob_removed():
    img, wire = _scene()
    img[20:60, 20:60] = (150, 152, 160)  # a grey tool far from the needle
    ys, xs = np.nonzero(wire)
    x, y = xs.min(), ys[np.argmin(xs)]
    img[y - 15 : y + 15, x - 15 : x + 5] = (190, 190, 196)  # a jaw holding the needle's end
    cov = wire.copy()
    cov[y - 15 : y + 15, x - 15 : x + 5] = True
    small = cv2.resize(cov.astype(np.float32), (240, 135), interpolation=cv2.INTER_AREA)
    view = refine_mask(img, coarse_components(small * 2.0), 4.0, max_half_width_px=4.0)
    full = _full(view, wire.shape)
    assert not full[20:60, 20:60].any()
    assert not full[y - 10 : y + 10, x - 12 : x].any()
    assert (full & wire).sum() > 0.8 * wire.sum()


def test_remove_thick_keeps_thin_lines():
    m = np.zeros((50, 50), bool)
    m[10:13, 5:45] = True
    assert (remove_thick(m, 3.0) == m).all()


def test_remove_thick_ignores_a_fat_speck_in_the_wire():
    """A wire a little fatter than the gate in one spot (a couple of deep pixels) keeps its
    pixels; a jaw-sized blob touching it is still removed."""
    m = np.zeros((60, 80), bool)
    m[28:34, 5:75] = True  # wire, 6 px wide (DT ≈ 3.5)
    m[26:35, 37:42] = True  # 9 px wide for 5 columns: one pixel deeper than the gate
    out = remove_thick(m, 4.0)
    assert (out == m).all()
    m[10:40, 60:80] = True  # a jaw
    out = remove_thick(m, 4.0)
    assert not out[10:40, 62:80].any() and out[28:34, 5:50].all()


def test_empty_coarse_mask_gives_empty_view():
    img, _ = _scene()
    view = refine_mask(img, np.zeros((135, 240), bool), 4.0)
    assert view.mask.size == 0


def test_coarse_blobs_farther_than_the_gap_are_dropped_near_ones_kept():
    prob = np.zeros((100, 200), np.float32)
    prob[40:44, 20:60] = 1.0  # the needle's larger piece
    prob[40:44, 70:85] = 1.0  # a piece beyond a 10 px occluder
    prob[90:94, 170:190] = 1.0  # another instrument's tip, far away
    everything = coarse_components(prob)
    assert everything[91, 180] and everything[41, 75]
    near = coarse_components(prob, max_gap=30.0)
    assert near[41, 30] and near[41, 75] and not near[91, 180]


def test_the_blob_at_the_keypoints_is_the_needle_even_when_a_jaw_is_larger():
    prob = np.zeros((100, 200), np.float32)
    prob[40:44, 20:50] = 1.0  # the needle
    prob[80:95, 150:190] = 1.0  # a larger jaw, far away
    jaw = coarse_components(prob, max_gap=30.0)
    assert jaw[90, 170] and not jaw[41, 30]
    needle = coarse_components(prob, max_gap=30.0, anchors=np.array([[21.0, 42.0], [48.0, 41.0]]))
    assert needle[41, 30] and not needle[90, 170]


def test_colour_test_passes_grey_metal_only():
    pink, grey, black, white = (215, 140, 132), (158, 161, 168), (20, 10, 10), (255, 255, 255)
    px = np.array([[pink, grey, black, white]], np.uint8)
    assert needle_coloured(px, ColourRule())[0].tolist() == [False, True, False, True]


def test_dark_pixels_must_be_neutral_to_pass():
    """A port hole or the cavity in shadow (dark, red-tinted) is not needle, nor is sensor
    noise on a black shaft; the needle in shadow (dark, neutral) and a bright, slightly warm
    highlight on it are."""
    port_hole, shaded_wire, warm_highlight = (44, 36, 34), (44, 44, 45), (180, 172, 170)
    noisy_black_shaft = (35, 35, 36)
    px = np.array([[port_hole, shaded_wire, warm_highlight, noisy_black_shaft]], np.uint8)
    assert needle_coloured(px, ColourRule())[0].tolist() == [False, True, True, False]


def _every_colour() -> np.ndarray:
    """All 2²⁴ 8-bit RGB colours as rows (N, 3) uint8."""
    v = np.arange(256, dtype=np.uint8)
    r, g, b = np.meshgrid(v, v, v, indexing="ij")
    return np.stack([r.ravel(), g.ravel(), b.ravel()], 1)


def test_colour_tests_equal_their_numpy_reductions_on_every_colour():
    """The channel sums written out give the same bits as numpy's ``mean(-1)`` and
    ``sum(-1)`` on every 8-bit colour: the colour tests' answers did not change."""
    rgb = _every_colour()
    c = rgb.astype(np.float32)
    level = np.maximum(c.mean(-1), 1.0)
    reference = (0.5 * (c[..., 0] + c[..., 2]) - c[..., 1]) / level
    np.testing.assert_array_equal(violet_score(rgb), reference)
    c16 = rgb.astype(np.int16)
    np.testing.assert_array_equal(channel_sum(c16), c16.sum(-1))


def test_the_integer_colour_test_equals_the_reference_on_every_colour():
    """8-bit images take the needle colour test in integers; every colour gets the answer
    of the int16 reference (level as sum / 3.0), at the nominal rule and at scaled ones whose
    levels fall between integers."""
    rgb = _every_colour().reshape(4096, 4096, 3)
    for gain in (1.0, 0.55, 0.4, 0.0):
        rule = ColourRule().at_exposure(gain)
        fast = needle_coloured(rgb, rule)
        reference = needle_coloured(rgb.astype(np.int16), rule)
        np.testing.assert_array_equal(fast, reference)


def test_a_dim_frame_scales_the_level_thresholds_not_the_colour_margins():
    rule = ColourRule()
    assert rule.at_exposure(0.95) is rule and rule.at_exposure(1.7) is rule  # nominal, bright
    dim = rule.at_exposure(0.4)
    k = 0.4 / 0.9
    assert np.isclose(dim.min_level, k * rule.min_level)
    assert np.isclose(dim.dark_level, k * rule.dark_level)
    assert np.isclose(dim.tissue_min_red_minus_blue, k * rule.tissue_min_red_minus_blue)
    assert dim.min_blue_minus_red == rule.min_blue_minus_red
    assert dim.dark_min_blue_minus_red == rule.dark_min_blue_minus_red
    # Never below the floors above sensor noise, however dark.
    black = rule.at_exposure(0.0)
    assert (black.min_level, black.dark_level, black.tissue_min_red_minus_blue) == (15, 20, 12)


def test_needle_and_tissue_at_gain_0_4_pass_the_dim_rule_only():
    # The needle's darker pixels and the pink tissue at 1 and at 0.4 × the light.
    needle = np.array([[[92, 95, 98]]], float)
    tissue = np.array([[[200, 130, 120]]], float)
    rule = ColourRule()
    for gain, passes in ((1.0, True), (0.4, False)):
        assert needle_coloured(np.rint(needle * gain).astype(np.uint8), rule)[0, 0] == passes
    dim = rule.at_exposure(0.4)
    assert needle_coloured(np.rint(needle * 0.4).astype(np.uint8), dim)[0, 0]
    c16 = np.rint(tissue * 0.35).astype(np.int16)
    assert (
        not tissue_coloured(c16, rule)[0, 0] and tissue_coloured(c16, rule.at_exposure(0.35))[0, 0]
    )
    # The cavity stays cavity in the dim rule.
    cavity = np.rint(np.array([[[24, 14, 14]]]) * 0.4).astype(np.int16)
    assert not tissue_coloured(cavity, dim)[0, 0]


def test_frame_exposure_reads_the_lit_tissue_and_follows_the_gain():
    img = np.zeros((108, 192, 3), np.uint8)
    img[30:90, 20:170] = (195, 125, 115)  # tissue at the nominal exposure
    img[50:60, 60:62] = (110, 112, 116)  # a needle
    assert np.isclose(frame_exposure(img), 1.0, atol=0.01)
    dim = np.rint(img * 0.4).astype(np.uint8)
    assert np.isclose(frame_exposure(dim), 0.4, atol=0.01)
