"""Jaw keypoints: positions agree with the DH kinematics, jaw tips are symmetric and distinct."""

import numpy as np
import pytest

from suture_bt.calibration.calibration_pose import CALIBRATION_JAW, CALIBRATION_POSES
from suture_bt.calibration.jaw_keypoints import (
    CLEVIS_CORNERS,
    JAW_HALF_THICKNESS,
    JAW_TIP_LENGTH,
    keypoints_in_base,
    keypoints_in_world,
    project_keypoints,
)
from suture_bt.calibration.scene_geometry import PSM_BASES, endoscope_model
from suture_bt.kinematics import frame_transforms


def test_clevis_corners_ride_on_frame_5_of_the_dh_chain(rng):
    q = rng.uniform(-0.8, 0.8, (5, 6))
    q[:, 2] = rng.uniform(0.05, 0.2, 5)
    kp = keypoints_in_base(q, 0.5)
    for i in range(5):
        T5 = frame_transforms(q[i])[4]
        for k in range(2):
            np.testing.assert_allclose(kp[i, k], T5[:3, :3] @ CLEVIS_CORNERS[k] + T5[:3, 3])
    # the corners are 6 mm apart along the pitch axis (frame-5 z)
    np.testing.assert_allclose(np.linalg.norm(kp[:, 0] - kp[:, 1], axis=1), 0.006)


def test_closed_jaw_tips_straddle_the_tool_tip_direction():
    q = CALIBRATION_POSES["psm1"]
    kp = keypoints_in_base(q, 0.0)[0]
    assert np.linalg.norm(kp[2] - kp[3]) == pytest.approx(2 * JAW_HALF_THICKNESS)
    frames = frame_transforms(q)
    yaw, tip = frames[5][:3, 3], frames[-1][:3, 3]  # yaw axis point, control point
    direction = (tip - yaw) / np.linalg.norm(tip - yaw)
    mid = (kp[2] + kp[3]) / 2
    np.testing.assert_allclose(mid, yaw + JAW_TIP_LENGTH * direction, atol=1e-12)


def test_open_jaw_tips_are_mirror_images_and_the_four_points_not_collinear():
    q = CALIBRATION_POSES["psm2"]
    kp = keypoints_in_base(q, CALIBRATION_JAW)[0]
    frames = frame_transforms(q)
    yaw, tip = frames[5][:3, 3], frames[-1][:3, 3]
    da, db = kp[2] - yaw, kp[3] - yaw
    reach = np.hypot(JAW_TIP_LENGTH, JAW_HALF_THICKNESS)
    assert np.linalg.norm(da) == pytest.approx(reach)
    assert np.linalg.norm(db) == pytest.approx(reach)
    bisector = (tip - yaw) / np.linalg.norm(tip - yaw)
    assert da @ bisector == pytest.approx(db @ bisector)  # symmetric about the jaw axis
    opening = np.arccos(da @ db / reach**2)
    assert opening == pytest.approx(
        CALIBRATION_JAW + 2 * np.arctan2(JAW_HALF_THICKNESS, JAW_TIP_LENGTH)
    )
    centred = kp - kp.mean(0)
    assert np.linalg.svd(centred, compute_uv=False)[1] > 1e-3  # rank ≥ 2: not collinear


def test_projection_matches_the_camera_model():
    cam = endoscope_model(640, 480).left
    q = CALIBRATION_POSES["psm1"]
    pw = keypoints_in_world(q, CALIBRATION_JAW, PSM_BASES["psm1"])[0]
    px = project_keypoints(q, CALIBRATION_JAW, PSM_BASES["psm1"], cam)[0]
    np.testing.assert_allclose(px, cam.project(pw))


def test_rejects_short_joint_vectors():
    with pytest.raises(ValueError, match="6 values"):
        keypoints_in_base(np.zeros((2, 3)), 0.1)
