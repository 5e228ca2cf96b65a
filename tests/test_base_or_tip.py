"""Base or tip: the swage band's colour decides, else the previous estimate; without either the
answer is a refusal, and a fit slid along its circle away from the band is refused."""

import dataclasses

import numpy as np
import pytest
from perception_helpers import random_needle_pose, stereo

from suture_bt.geometry import NeedleModel
from suture_bt.perception.base_or_tip import BaseTipChooser
from suture_bt.perception.base_or_tip import on_mask as _on_mask
from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.needle_projection import rasterize_needle
from suture_bt.perception.pose_fit import MaskView, NeedleNotFound
from suture_bt.transforms import invert, make_transform


class _Chooser:
    """What these tests read of a localiser: its model and its base/tip chooser."""

    def __init__(self, st):
        self.model = NeedleModel()
        self.base_tip = BaseTipChooser(st, self.model, ColourRule())


def test_without_the_band_the_ends_follow_the_previous_estimate_or_are_refused():
    """A needle whose swage band is not seen: base and tip look alike, so the localiser keeps
    the orientation nearer the previous estimate, and without one refuses to guess."""
    st = stereo(960, 540)
    loc = _Chooser(st)
    T = random_needle_pose(np.random.default_rng(3), 0.08, 0.12)
    images, views = [], []
    for cam in (st.left, st.right):
        mask = rasterize_needle(cam, invert(cam.T_world_cam) @ st.left.T_world_cam @ T, loc.model)
        img = np.empty((540, 960, 3), np.uint8)
        img[:] = (215, 140, 132)
        img[mask] = (158, 161, 168)  # grey all along: no violet band
        images.append(img)
        views.append(MaskView(mask))
    with pytest.raises(NeedleNotFound, match="which end is the base"):
        loc.base_tip.orient(T, images, views, 3.0, None)
    for previous in (T, loc.model.swapped(T)):
        out, _, decided_by = loc.base_tip.orient(T, images, views, 3.0, previous)
        assert decided_by == "previous"
        np.testing.assert_allclose(out, previous, atol=1e-9)


def _banded(st, T, model):
    """Images (pink, grey wire, violet first 3 mm) and full masks of a needle at T."""
    band = dataclasses.replace(model, tip_angle=model.base_angle - 0.003 / model.radius)
    images, views = [], []
    for cam in (st.left, st.right):
        Tc = invert(cam.T_world_cam) @ st.left.T_world_cam @ T
        mask = rasterize_needle(cam, Tc, model)
        img = np.empty((540, 960, 3), np.uint8)
        img[:] = (215, 140, 132)
        img[mask] = (158, 161, 168)
        img[rasterize_needle(cam, Tc, band)] = (150, 60, 170)
        images.append(img)
        views.append(MaskView(mask))
    return images, views


def test_a_fit_slid_along_its_circle_away_from_the_band_is_refused():
    """The swage band marks the first 3 mm of the arc: a pose whose base lies 8 mm before the
    seen band (its arc moved along the same circle) is refused, the right pose kept."""
    st = stereo(960, 540)
    loc = _Chooser(st)
    T = random_needle_pose(np.random.default_rng(3), 0.08, 0.12)
    images, views = _banded(st, T, loc.model)
    out, _, decided_by = loc.base_tip.orient(T, images, views, 3.0, None)
    assert decided_by == "colour"
    np.testing.assert_allclose(out, T, atol=1e-9)
    a = 0.008 / loc.model.radius
    turn = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(NeedleNotFound, match="slid along the needle's circle"):
        loc.base_tip.orient(T @ make_transform(turn), images, views, 3.0, None)


def test_a_fit_that_swings_its_base_off_the_seen_band_is_refused():
    """A pose turned about its tip (the seen tip piece kept, the hidden rest misplaced) puts
    its base beside the violet band, not through it: refused, naming the miss."""
    st = stereo(960, 540)
    loc = _Chooser(st)
    T = random_needle_pose(np.random.default_rng(3), 0.08, 0.12)
    images, views = _banded(st, T, loc.model)
    half_width = loc.model.wire_radius * st.left.fx / T[2, 3]
    loc.base_tip.orient(T, images, views, half_width, None)  # the right pose passes
    tip = T[:3, :3] @ loc.model.tip + T[:3, 3]
    a = np.deg2rad(12.0)
    R = np.array([[1.0, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    swung = make_transform(R @ T[:3, :3], R @ (T[:3, 3] - tip) + tip)
    with pytest.raises(NeedleNotFound, match="swage band lies .* off the fitted arc"):
        loc.base_tip.orient(swung, images, views, half_width, None)


def test_an_end_counts_as_seen_only_on_or_next_to_the_mask():
    mask = np.zeros((20, 30), bool)
    mask[10, 5:15] = True  # a 1-px line at full-image row 110, columns 205-214
    view = MaskView(mask, (200, 100))
    assert _on_mask(view, np.array([210.0, 110.0]), 2.0)
    assert _on_mask(view, np.array([216.0, 110.0]), 2.0)  # 2 px past the last pixel
    assert not _on_mask(view, np.array([217.5, 110.0]), 2.0)
    assert not _on_mask(view, np.array([210.0, 107.0]), 2.0)
    assert not _on_mask(view, np.array([50.0, 50.0]), 2.0)  # outside the crop


def test_an_end_where_the_wire_would_go_on_into_the_tissue_counts_as_cut():
    """A tissue model (world points, margin → inside) below z = 0 and an upright needle whose
    tip touches the surface, the circle going on down into it: the tip is cut there, the base
    (up in the air) is not; without a tissue model nothing is."""
    st = stereo(960, 540)
    model = NeedleModel()
    arc = model.point_at(np.linspace(model.tip_angle, model.base_angle, 50))
    past_tip = model.point_at(model.tip_angle - 0.002 / model.radius)
    past_base = model.point_at(model.base_angle + 0.002 / model.radius)
    upright = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # needle y → z
    for a in np.radians(np.arange(0.0, 360.0, 5.0)):
        turn = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0, np.cos(a)]])
        R = turn @ upright
        z = lambda p, R=R: (p - model.tip) @ R.T  # noqa: E731 - tip at the origin
        ends = z(np.stack([past_tip, past_base]))[:, 2]
        if np.all(z(arc)[:, 2] >= -1e-9) and ends[0] < -0.0005 < 0.0005 < ends[1]:
            break
    else:
        pytest.fail("no upright pose with the circle going on into the tissue past the tip")
    T_world = np.eye(4)
    T_world[:3, :3], T_world[:3, 3] = R, -R @ model.tip

    def below(world, margin=0.0):
        return np.asarray(world)[:, 2] < -margin

    T_cam = st.left.T_cam_world @ T_world
    assert BaseTipChooser(st, model, ColourRule(), below).ends_in_tissue(T_cam) == (False, True)
    assert BaseTipChooser(st, model, ColourRule()).ends_in_tissue(T_cam) == (False, False)
