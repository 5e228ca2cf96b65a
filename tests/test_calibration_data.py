"""Calibration data: labels from the sim's link frames match the keypoint model, and a rendered
window matches the same window cut from a full capture (what calibrate() sees)."""

import numpy as np

from suture_bt.calibration.jaw_keypoints import keypoints_in_world
from suture_bt.calibration.keypoint_net import extract_window
from suture_bt.calibration.scene_geometry import PSM_BASES
from suture_bt.datagen.calibration_data import CalibrationScenes, generate, render_window


def test_labels_and_windows_match_the_capture_pipeline(tmp_path):
    scenes = CalibrationScenes()
    try:
        rng = np.random.default_rng(3)
        q_meas, offset, win, kp = scenes.sample(rng, "psm2")
        body = scenes.world.arms["psm2"].body
        q = q_meas.copy()
        q[:3] += offset
        model = scenes.cam.project(keypoints_in_world(q, body.jaw, PSM_BASES["psm2"])[0])
        np.testing.assert_allclose(kp, model, atol=1e-3)  # px
        kw = win.to_window(kp)
        assert np.all((kw > 0) & (kw < 255))
        rendered = render_window(scenes.world.client, scenes.cam, win).astype(float)
        captured = extract_window(scenes.world.camera.capture().left, win).astype(float)
        assert np.abs(rendered - captured).mean() < 1.5  # grey levels
    finally:
        scenes.close()
    meta = generate(2, tmp_path, seed=1)
    assert meta["n"] == 2 and (tmp_path / "calibration_0000.npz").exists()
    data = dict(np.load(tmp_path / "calibration_0000.npz"))
    assert data["images"].shape == (2, 256, 256, 3) and data["keypoints"].shape == (2, 4, 2)
    assert data["arm"].tolist() == [0, 1]
