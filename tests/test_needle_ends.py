"""Base↔tip choice from the swage band's colour: right pose kept, swapped pose flagged."""

import dataclasses

import numpy as np
from perception_helpers import stereo

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_ends import (
    BAND_LENGTH,
    MIN_EVIDENCE,
    band_miss_px,
    band_offset,
    base_evidence,
    violet_score,
    with_band_pieces,
)
from suture_bt.perception.needle_projection import project_cam, rasterize_needle, transform_points
from suture_bt.perception.pose_fit import MaskView
from suture_bt.transforms import invert, make_transform

MODEL = NeedleModel()
BAND = dataclasses.replace(MODEL, tip_angle=MODEL.base_angle - 0.003 / MODEL.radius)
PINK, GREY, VIOLET = (215, 140, 132), (158, 161, 168), (150, 60, 170)


def _scene(T_left_needle: np.ndarray, band_colour=VIOLET):
    """Images, masks and cameras of a synthetic needle with a coloured base band."""
    st = stereo(960, 540)
    images, views = [], []
    for cam in (st.left, st.right):
        T = invert(cam.T_world_cam) @ st.left.T_world_cam @ T_left_needle
        full = rasterize_needle(cam, T, MODEL)
        band = rasterize_needle(cam, T, BAND)
        img = np.empty((540, 960, 3), np.uint8)
        img[:] = PINK
        img[full] = GREY
        img[band] = band_colour
        images.append(img)
        views.append(MaskView(full))
    return tuple(images), tuple(views), (st.left, st.right)


def _pose() -> np.ndarray:
    R = np.array([[1.0, 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]])
    return make_transform(R, (0.004, -0.002, 0.1))


def test_swap_is_a_half_turn_that_exchanges_the_ends():
    R = MODEL.swap_rotation()
    assert np.allclose(R @ R, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(R @ MODEL.base, MODEL.tip, atol=1e-12)
    T = _pose()
    Ts = MODEL.swapped(T)
    assert np.allclose(Ts[:3, 3], T[:3, 3])
    assert np.allclose(MODEL.swapped(Ts), T)


def test_violet_band_scores_high_and_metal_near_zero():
    s = violet_score(np.array([[VIOLET, GREY, (255, 120, 255), (255, 255, 255)]], np.uint8))[0]
    assert s[0] > 0.6 and s[2] > 0.5
    assert abs(s[1]) < 0.05 and abs(s[3]) < 0.01


def test_band_colour_tells_the_right_pose_from_its_swap():
    T = _pose()
    images, views, cams = _scene(T)
    right = base_evidence(images, views, cams, T, MODEL)
    wrong = base_evidence(images, views, cams, MODEL.swapped(T), MODEL)
    assert right > MIN_EVIDENCE
    assert wrong < -MIN_EVIDENCE


def test_no_band_leaves_the_choice_undecided_or_says_swapped():
    T = _pose()
    images, views, cams = _scene(T, band_colour=GREY)
    # Both ends grey: the fitted base end votes "swapped", the tip end votes "right".
    assert abs(base_evidence(images, views, cams, T, MODEL)) < MIN_EVIDENCE


def test_needle_outside_the_masks_gives_zero_evidence():
    T = _pose()
    images, _, cams = _scene(T)
    empty = (MaskView(np.zeros((540, 960), bool)),) * 2
    assert base_evidence(images, empty, cams, T, MODEL) == 0.0


def test_band_position_decides_when_the_fit_is_a_few_pixels_off():
    """A rough fit (3 mm off, ends not on the band's pixels): the band's position still votes
    for the pose whose base is nearer the violet pixels."""
    T = _pose()
    images, views, cams = _scene(T)
    rough = T.copy()
    rough[:3, 3] += (0.0015, -0.0015, 0.002)
    assert base_evidence(images, views, cams, rough, MODEL) > MIN_EVIDENCE
    assert base_evidence(images, views, cams, MODEL.swapped(rough), MODEL) < -MIN_EVIDENCE


def _slid(T: np.ndarray, angle: float) -> np.ndarray:
    """The pose turned by ``angle`` about its own arc axis: the same circle, the arc moved
    along it (base further round)."""
    c, s = np.cos(angle), np.sin(angle)
    return T @ make_transform(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]))


def test_band_offset_is_inside_the_band_for_the_right_pose_and_grows_as_the_fit_slides():
    T = _pose()
    images, views, cams = _scene(T)
    assert 0.0 <= band_offset(images, views, cams, T, MODEL) < BAND_LENGTH
    # Slid by 8 mm of arc, base first: the seen band now starts 8 mm along the fitted arc.
    slid = band_offset(images, views, cams, _slid(T, 0.008 / MODEL.radius), MODEL)
    assert abs(slid - 0.008) < 0.0015
    # No band seen, no offset.
    grey = _scene(T, band_colour=GREY)
    assert band_offset(*grey, T, MODEL) is None


def _swung(T: np.ndarray, deg: float) -> np.ndarray:
    """The pose turned by ``deg`` about the camera's x axis through its tip: the tip stays, the
    base swings away (a fit that explains a seen tip piece and misplaces the hidden rest)."""
    tip = T[:3, :3] @ MODEL.tip + T[:3, 3]
    a = np.deg2rad(deg)
    R = np.array([[1.0, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    return make_transform(R @ T[:3, :3], R @ (T[:3, 3] - tip) + tip)


def test_band_miss_is_inside_the_wire_for_the_right_pose_and_grows_as_the_fit_swings():
    T = _pose()
    images, _, cams = _scene(T)
    half_width = MODEL.wire_radius * cams[0].fx / T[2, 3]
    reach = 30.0
    assert band_miss_px(images, cams, T, MODEL, reach) < 0.6 * half_width
    swung = band_miss_px(images, cams, _swung(T, 15.0), MODEL, reach)
    assert swung > 3.0 * half_width
    # Beyond the reach the band is not looked at; no band seen, no miss.
    assert band_miss_px(images, cams, _swung(T, 15.0), MODEL, 1.0) is None
    assert band_miss_px(_scene(T, band_colour=GREY)[0], cams, T, MODEL, reach) is None


def _base_pixel(cam, T_left_needle: np.ndarray, cams) -> np.ndarray:
    T = invert(cam.T_world_cam) @ cams[0].T_world_cam @ T_left_needle
    return project_cam(cam, transform_points(T, MODEL.base[None]))[0]


def test_grey_at_an_end_touching_an_occluder_does_not_vote():
    """The band hidden behind a jaw: only the visible grey end votes, and it is the tip."""
    T = _pose()
    images, views, cams = _scene(T, band_colour=GREY)
    base_px = [_base_pixel(cam, T, cams) for cam in cams]

    def hidden(eye: int, uv: np.ndarray) -> bool:
        return bool(np.linalg.norm(uv - base_px[eye]) < 5.0)

    assert base_evidence(images, views, cams, T, MODEL, end_hidden=hidden) > MIN_EVIDENCE
    flipped = MODEL.swapped(T)
    assert base_evidence(images, views, cams, flipped, MODEL, end_hidden=hidden) < -MIN_EVIDENCE


def _band_cut_off(T: np.ndarray):
    """Left image, its camera and a mask that lacks the band (a jaw cut it off)."""
    images, views, cams = _scene(T)
    cam = cams[0]
    T_cam = invert(cam.T_world_cam) @ cams[0].T_world_cam @ T
    band = rasterize_needle(cam, T_cam, BAND)
    ys, xs = np.nonzero(views[0].mask & ~band)
    crop = (views[0].mask & ~band)[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    return images[0], MaskView(crop, (int(xs.min()), int(ys.min()))), band, cam


def test_band_piece_cut_off_from_the_mask_is_added_back():
    T = _pose()
    img, view, band, cam = _band_cut_off(T)
    out = with_band_pieces(img, view, 100.0, 0.05, cam, MODEL.wire_radius)
    full = np.zeros(img.shape[:2], bool)
    h, w = out.mask.shape
    full[out.origin[1] : out.origin[1] + h, out.origin[0] : out.origin[0] + w] = out.mask
    assert full[band].all()
    assert (full & ~band).sum() == view.mask.sum()


def test_violet_blobs_too_far_or_too_large_are_not_band():
    T = _pose()
    img, view, band, cam = _band_cut_off(T)
    xs, ys = view.origin
    far = img.copy()
    far[band] = PINK
    far[:10, :10] = VIOLET  # a small violet square far from the needle
    out = with_band_pieces(far, view, 40.0, 0.05, cam, MODEL.wire_radius)
    assert out.mask.sum() == view.mask.sum()
    big = img.copy()
    big[ys - 60 : ys - 20, xs : xs + 200] = VIOLET  # a large violet plate
    big[band] = PINK
    out = with_band_pieces(big, view, 100.0, 0.05, cam, MODEL.wire_radius)
    assert out.mask.sum() == view.mask.sum()
