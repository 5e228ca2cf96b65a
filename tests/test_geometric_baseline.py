"""PnP baseline: exact keypoints give the offset back; noise gives a bounded error."""

import numpy as np
import pytest

from suture_bt.calibration.calibration_pose import CALIBRATION_JAW, CALIBRATION_POSES
from suture_bt.calibration.geometric_baseline import joints123_from_pitch_point, pnp_offset
from suture_bt.calibration.jaw_keypoints import project_keypoints
from suture_bt.calibration.scene_geometry import PSM_BASES, endoscope_model
from suture_bt.kinematics import frame_transforms


def test_closed_form_inverts_the_pitch_point(rng):
    for _ in range(5):
        q = np.r_[rng.uniform(-0.8, 0.8, 2), rng.uniform(0.05, 0.2), rng.uniform(-1, 1, 3)]
        p = frame_transforms(q)[4][:3, 3]  # wrist-pitch point
        np.testing.assert_allclose(joints123_from_pitch_point(p), q[:3], atol=1e-12)


@pytest.mark.parametrize("arm", ["psm1", "psm2"])
def test_exact_keypoints_recover_the_offset(arm, rng):
    cam = endoscope_model().left
    q_meas = CALIBRATION_POSES[arm] + rng.uniform(-0.01, 0.01, 6)
    offset = np.array([np.deg2rad(3.0), np.deg2rad(-4.0), 0.004])
    q_true = q_meas.copy()
    q_true[:3] += offset
    px = project_keypoints(q_true, CALIBRATION_JAW, PSM_BASES[arm], cam)[0]
    est = pnp_offset(px, q_meas, CALIBRATION_JAW, PSM_BASES[arm], cam)
    np.testing.assert_allclose(est, offset, atol=2e-5)  # PnP iteration tolerance


def test_noisy_keypoints_give_a_bounded_error(rng):
    cam = endoscope_model().left
    q = CALIBRATION_POSES["psm1"]
    px = project_keypoints(q, CALIBRATION_JAW, PSM_BASES["psm1"], cam)[0]
    errs = [
        pnp_offset(px + rng.normal(0, 1.0, px.shape), q, CALIBRATION_JAW, PSM_BASES["psm1"], cam)
        for _ in range(20)
    ]
    err = np.abs(np.array(errs)) / np.array([np.deg2rad(1), np.deg2rad(1), 1e-3])
    assert np.all(err.mean(0) < 2.0)  # within 2° / 2 mm at 1 px noise (PnP has 6 DoF)
