"""Refining a joint-offset estimate by the keypoint reprojection error (kinematics and camera)."""

import numpy as np

from suture_bt.calibration.calibration_pose import CALIBRATION_JAW, CALIBRATION_POSES, OFFSET_BOUND
from suture_bt.calibration.jaw_keypoints import project_keypoints
from suture_bt.calibration.reprojection_refine import refine_offset
from suture_bt.calibration.scene_geometry import PSM_BASES
from suture_bt.sim.camera import stereo_model

CAM = stereo_model(1920, 1080).left


def _keypoints(arm: str, offset: np.ndarray, noise_px: float, rng) -> np.ndarray:
    q = np.array(CALIBRATION_POSES[arm], dtype=float)
    q[:3] += offset
    kp = project_keypoints(q, CALIBRATION_JAW, PSM_BASES[arm], CAM)[0]
    return kp + rng.normal(0.0, noise_px, kp.shape)


def test_a_shrunken_estimate_at_the_box_corner_is_taken_to_the_offset_the_keypoints_show():
    """The MLP's failure mode at the box's corners: an answer pulled toward the middle."""
    rng = np.random.default_rng(0)
    for arm in ("psm1", "psm2"):
        truth = np.array([1.0, -1.0, 1.0]) * OFFSET_BOUND
        kp = _keypoints(arm, truth, 0.3, rng)
        start = 0.9 * truth
        q_meas = np.array(CALIBRATION_POSES[arm], dtype=float)
        got = refine_offset(start, kp, q_meas, CALIBRATION_JAW, PSM_BASES[arm], CAM, 1.0)
        err = np.abs(got - truth) / np.array([np.deg2rad(1.0), np.deg2rad(1.0), 1e-3])
        assert np.all(err < [0.05, 0.05, 0.1]), err  # deg, deg, mm
        assert np.all(np.abs(start - truth) > np.abs(got - truth))


def test_exact_keypoints_leave_the_exact_offset_where_it_is():
    rng = np.random.default_rng(1)
    truth = np.array([0.3, 0.5, -0.2]) * OFFSET_BOUND
    kp = _keypoints("psm1", truth, 0.0, rng)
    q_meas = np.array(CALIBRATION_POSES["psm1"], dtype=float)
    got = refine_offset(truth, kp, q_meas, CALIBRATION_JAW, PSM_BASES["psm1"], CAM, 1.0)
    np.testing.assert_allclose(got, truth, atol=1e-9)
