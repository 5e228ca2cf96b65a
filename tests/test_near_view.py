"""A near needle measured on the halved images (:mod:`suture_bt.perception.near_view`): the
halved cameras see what the decimated images show, only near frames are halved, a Task 3
start is answered there as well as at full resolution, a halved refusal stands without priors
and goes to full resolution with them, and a frame whose masks say the needle is not near is
measured at full resolution."""

import numpy as np
import pytest
from perception_helpers import pose_errors, stereo, task_scene

from suture_bt.perception import needle_localizer
from suture_bt.perception.near_view import (
    HALF_RES_DEPTH,
    confirms_near,
    halved,
    halved_camera,
    halved_pixels,
    halved_stereo,
    wants_half,
)
from suture_bt.perception.needle_localizer import NeedleLocalizer
from suture_bt.perception.pose_fit import NeedleNotFound


def test_the_halved_camera_sees_a_point_where_the_decimated_image_shows_it():
    full = stereo(1920, 1080)
    half = halved_stereo(full)
    assert (half.left.width, half.left.height) == (960, 540)
    assert np.isclose(half.baseline, full.baseline)
    rng = np.random.default_rng(0)
    cam = full.left
    pc = np.column_stack([rng.uniform(-0.02, 0.02, (50, 2)), rng.uniform(0.03, 0.2, 50)])
    pw = pc @ cam.T_world_cam[:3, :3].T + cam.T_world_cam[:3, 3]
    assert np.allclose(halved_camera(cam).project(pw), halved_pixels(cam.project(pw)))
    img = rng.integers(0, 256, (1080, 1920, 3), dtype=np.uint8)
    small = halved(img)
    assert small.shape == (540, 960, 3) and small.flags.c_contiguous
    assert np.array_equal(small[7, 11], img[14, 22])  # pixel 2i of the full image is pixel i


def test_only_near_frames_of_even_size_are_halved_and_kept_so_only_when_the_masks_agree():
    even, odd = (1080, 1920, 3), (1081, 1920, 3)
    assert wants_half(0.035, even)
    assert not wants_half(None, even)  # no keypoint depth: full resolution
    assert not wants_half(HALF_RES_DEPTH + 0.005, even)
    assert not wants_half(0.035, odd)
    assert confirms_near(0.035) and not confirms_near(None) and not confirms_near(0.08)


def test_a_task_3_start_is_measured_halved_as_well_as_at_full_resolution():
    stereo_model, left, right, T, priors, tissue = task_scene("held_start", 10)
    assert T[2, 3] < 0.035
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    est = loc.localize(left, right)
    assert est.pixel_scale == 2.0 and est.masks[0].mask.shape[0] < 540
    pos, ang = pose_errors(est.T_cam_needle, T)
    assert pos < 0.1 and ang < 0.5  # 0.01 mm / 0.05 deg
    loc.halve_near = False
    full = loc.localize(left, right)
    assert full.pixel_scale == 1.0
    pos, ang = pose_errors(est.T_cam_needle, full.T_cam_needle)
    assert pos < 0.1 and ang < 0.5


def test_a_refusal_on_the_halved_images_stands_without_priors_and_with_them_is_measured_again(
    monkeypatch,
):
    """Scene 7 (a Task 3 start 33 mm away) is refused on the halved images without priors
    (predicted spread 16 deg) and answered at full resolution; with priors the halved images
    answer it. A halved refusal with priors is measured again at full resolution."""
    stereo_model, left, right, T, priors, tissue = task_scene("held_start", 7)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    with pytest.raises(NeedleNotFound, match="measured on the halved images"):
        loc.localize(left, right)
    assert loc.localize(left, right, priors=priors).pixel_scale == 2.0
    loc.halve_near = False
    want = loc.localize(left, right, priors=priors)
    loc.halve_near = True
    measure = NeedleLocalizer._measure

    def halved_refuses(self, images, *args, **kwargs):
        if self.pixel_scale == 2.0:
            raise NeedleNotFound("refused on the halved images")
        return measure(self, images, *args, **kwargs)

    monkeypatch.setattr(NeedleLocalizer, "_measure", halved_refuses)
    est = loc.localize(left, right, priors=priors)
    assert est.pixel_scale == 1.0 and np.array_equal(est.T_cam_needle, want.T_cam_needle)


def test_a_frame_whose_masks_put_the_needle_far_is_measured_at_full_resolution(monkeypatch):
    """Keypoints matched wrongly between the eyes could call a far needle near: the halved
    masks' own disparity sends the frame back, and it is answered as if never halved."""
    stereo_model, left, right, T, priors, tissue = task_scene("in_port", 2)
    assert T[2, 3] > 0.07
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    loc.halve_near = False
    try:
        want = loc.localize(left, right, priors=priors).T_cam_needle
    except NeedleNotFound as exc:
        want = exc.reason
    loc.halve_near = True
    monkeypatch.setattr(needle_localizer, "wants_half", lambda depth, shape: True)
    try:
        est = loc.localize(left, right, priors=priors)
        assert est.pixel_scale == 1.0 and np.array_equal(est.T_cam_needle, want)
    except NeedleNotFound as exc:
        assert exc.reason == want
