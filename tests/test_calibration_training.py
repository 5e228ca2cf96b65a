"""Regressor training on projected keypoints: data follow the offset model; a short run learns."""

import numpy as np
import pytest

from suture_bt.calibration.calibration_pose import CALIBRATION_JAW, OFFSET_BOUND
from suture_bt.calibration.jaw_keypoints import project_keypoints
from suture_bt.calibration.scene_geometry import PSM_BASES, endoscope_model
from suture_bt.calibration.training import projected_dataset, train_arm, train_regressor


def test_projected_data_are_keypoints_of_measured_plus_offset():
    d = projected_dataset("psm1", 50, seed=3)
    assert np.all(np.abs(d.offsets) <= OFFSET_BOUND)
    q = d.q_meas.copy()
    q[:, :3] += d.offsets
    px = project_keypoints(q, CALIBRATION_JAW, PSM_BASES["psm1"], endoscope_model().left)
    np.testing.assert_allclose(d.pixels, px)
    again = projected_dataset("psm1", 50, seed=3)
    np.testing.assert_array_equal(again.offsets, d.offsets)


def test_short_training_beats_predicting_zero():
    data = projected_dataset("psm2", 2000, seed=1)
    model = train_arm("psm2", data, epochs=5, seed=0, progress=False)
    test = projected_dataset("psm2", 300, seed=2)
    from suture_bt.calibration.offset_regressor import regressor_features

    pred = model.predict(regressor_features("psm2", test.pixels, test.q_meas))
    err = np.abs(pred - test.offsets).mean(0)
    baseline = np.abs(test.offsets).mean(0)
    assert np.all(err < 0.7 * baseline), (err, baseline)  # untrained: ≈ 1.0
    assert np.mean(err / baseline) < 0.5


def test_training_is_seeded():
    a = train_regressor(200, seed=4, epochs=1, progress=False)
    b = train_regressor(200, seed=4, epochs=1, progress=False)
    x = np.zeros((1, 4, 2)) + 700.0
    q = np.array(a.meta["poses"]["psm1"])[None]
    np.testing.assert_array_equal(
        a.predict("psm1", x, 1920, 1080, q), b.predict("psm1", x, 1920, 1080, q)
    )


def test_shipped_regressor_meets_the_accuracy_target_on_projected_keypoints():
    from suture_bt.calibration.offset_regressor import OffsetRegressor
    from suture_bt.calibration.training import noisy

    reg = OffsetRegressor.load()
    rng = np.random.default_rng(5)
    for arm in ("psm1", "psm2"):
        d = projected_dataset(arm, 400, seed=4242)  # a seed never used in training
        pred = reg.predict(arm, noisy(d.pixels, rng, 1.0), 1920, 1080, d.q_meas)
        err = np.abs(pred - d.offsets) / np.array([np.pi / 180, np.pi / 180, 1e-3])
        assert np.all(err.mean(0) < 0.1), err.mean(0)  # (deg, deg, mm); target 0.2


def test_a_missing_dataset_fails_before_anything_is_trained_or_written(tmp_path):
    """`suture-bt train calibration --data <typo>` used to train the regressor, save it over
    the packaged one, and only then fail on the missing windows."""
    from suture_bt.calibration.training import train_calibration

    out = tmp_path / "weights"
    out.mkdir()
    with pytest.raises(FileNotFoundError, match="suture-bt data calibration"):
        train_calibration(tmp_path / "no_such_folder", out, progress=False)
    assert not any(out.iterdir())
