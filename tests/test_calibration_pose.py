"""Calibration poses: Δq → keypoint pixels is injective and well conditioned over the bounds."""

import numpy as np
import pytest

from suture_bt.calibration.calibration_pose import (
    CALIBRATION_POSES,
    OFFSET_BOUND,
    actual_joints,
    expected_keypoints,
    offset_box_points,
    uniqueness_report,
)
from suture_bt.calibration.scene_geometry import endoscope_model
from suture_bt.kinematics import limit_violations


@pytest.mark.parametrize("arm", ["psm1", "psm2"])
def test_pose_identifies_the_offset_uniquely(arm):
    rep = uniqueness_report(arm, samples=8000, grid_levels=5)
    assert rep.ok, rep
    assert rep.max_condition_number < 20
    assert rep.min_singular_value > 4.0  # px per degree / mm at 1920×1080
    assert np.all(rep.worst_crb_std < 0.2)  # (deg, deg, mm) per px of keypoint noise
    assert rep.pairs_checked > 0  # the KD-tree test did compare close keypoint vectors
    assert rep.min_depth > 0.02 and rep.min_margin_px > 20


@pytest.mark.parametrize("arm", ["psm1", "psm2"])
def test_every_offset_keeps_the_pose_inside_the_joint_limits(arm):
    for q in actual_joints(CALIBRATION_POSES[arm], offset_box_points(3)):
        assert not limit_violations(q)


def test_the_check_fails_when_pixels_cannot_resolve_the_offset():
    # At 64×36 px one degree of offset moves the keypoints by a fraction of a pixel, so offsets
    # degrees apart give keypoint vectors within the 3 px tolerance: not injective at that noise.
    cam = endoscope_model(64, 36).left
    rep = uniqueness_report("psm1", cam, samples=4000, grid_levels=3)
    assert not rep.injective and not rep.ok


def test_offset_box_spans_the_bounds():
    pts = offset_box_points(3)
    assert pts.shape == (27, 3)
    np.testing.assert_allclose(np.abs(pts).max(0), OFFSET_BOUND)


def test_expected_keypoints_move_with_the_offset():
    cam = endoscope_model().left
    q = CALIBRATION_POSES["psm1"]
    a = expected_keypoints("psm1", q, cam)
    b = expected_keypoints("psm1", q, cam, offset=[np.deg2rad(1), 0, 0])
    assert np.linalg.norm(b - a, axis=1).min() > 5.0


def test_unknown_arm_is_rejected():
    with pytest.raises(ValueError, match="unknown arm"):
        uniqueness_report("ecm")
