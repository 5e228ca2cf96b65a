"""Offset regressor: MLP shapes, standard scaling, pixel rescaling and weight round trip."""

import numpy as np
import pytest
import torch
from weights_helpers import Evil, assert_refused

from suture_bt.calibration.calibration_pose import CALIBRATION_POSES
from suture_bt.calibration.offset_regressor import (
    HIDDEN,
    NUM_INPUTS,
    WEIGHTS_PATH,
    OffsetMLP,
    OffsetRegressor,
    new_regressor,
    regressor_features,
    to_reference_pixels,
)
from suture_bt.weights_file import WeightsError


def test_architecture_is_400_300_200_relu():
    m = OffsetMLP()
    linears = [layer for layer in m.net if isinstance(layer, torch.nn.Linear)]
    assert [layer.out_features for layer in linears] == [*HIDDEN, 3]
    assert linears[0].in_features == NUM_INPUTS == 14
    assert sum(isinstance(layer, torch.nn.ReLU) for layer in m.net) == 3


def test_scaling_standardises_inputs_and_inverts_outputs(rng):
    m = OffsetMLP()
    x = rng.normal(5.0, 3.0, (500, NUM_INPUTS))
    y = rng.normal(-2.0, 0.01, (500, 3))
    m.set_scaling(x, y)
    xs = m.scale_x(x).numpy()
    np.testing.assert_allclose(xs.mean(0), 0, atol=1e-5)
    np.testing.assert_allclose(xs.std(0, ddof=1), 1, atol=1e-4)
    # predict de-scales: with a zero last layer the output is exactly the target mean
    torch.nn.init.zeros_(m.net[-1].weight)
    torch.nn.init.zeros_(m.net[-1].bias)
    np.testing.assert_allclose(m.predict(x[:3]), np.tile(y.mean(0), (3, 1)), atol=1e-12)


def test_reference_pixels_keep_the_pixel_centre_convention():
    # centre pixel of a 640×360 image is the centre of the 1920×1080 image
    c = to_reference_pixels(np.array([319.5, 179.5]), 640, 360)
    np.testing.assert_allclose(c, [959.5, 539.5])
    np.testing.assert_allclose(to_reference_pixels(np.array([3.0, 4.0]), 1920, 1080), [3.0, 4.0])


def test_features_subtract_the_calibration_pose_and_check_shapes():
    q = CALIBRATION_POSES["psm2"][None] + 0.01
    f = regressor_features("psm2", np.zeros((1, 4, 2)), q)
    assert f.shape == (1, 14)
    np.testing.assert_allclose(f[0, 8:], 0.01)
    with pytest.raises(ValueError, match="one 6-joint vector"):
        regressor_features("psm2", np.zeros((2, 4, 2)), q)


def test_save_load_round_trip_and_pose_guard(tmp_path):
    reg = new_regressor()
    path = tmp_path / "r.pt"
    reg.save(path)
    back = OffsetRegressor.load(path)
    x = np.zeros((2, 4, 2)) + 500.0
    q = np.tile(CALIBRATION_POSES["psm1"], (2, 1))
    np.testing.assert_allclose(
        back.predict("psm1", x, 1920, 1080, q), reg.predict("psm1", x, 1920, 1080, q)
    )
    reg.meta["poses"]["psm1"] = np.zeros(6)  # numpy in meta is stored as a plain list
    reg.save(path)
    with pytest.raises(WeightsError, match="another calibration pose of psm1"):
        OffsetRegressor.load(path)
    reg.meta["poses"]["psm1"] = CALIBRATION_POSES["psm1"]
    reg.meta["jaw"] = np.float64(0.5)
    reg.save(path)
    with pytest.raises(WeightsError, match="jaw angle 0.5"):
        OffsetRegressor.load(path)
    with pytest.raises(FileNotFoundError, match="suture-bt train calibration"):
        OffsetRegressor.load(tmp_path / "missing.pt")


def test_shipped_weights_load_data_only():
    reg = OffsetRegressor.load()
    assert sorted(reg.models) == ["psm1", "psm2"] and reg.meta["reference_size"] == [1920, 1080]
    blob = torch.load(WEIGHTS_PATH, map_location="cpu", weights_only=True)
    assert blob["format"] == "suture_bt.offset_regressor.v1"


def test_bad_weights_files_raise_one_line_errors(tmp_path):
    marker = tmp_path / "ran"
    evil = tmp_path / "evil.pt"
    torch.save({"format": "suture_bt.offset_regressor.v1", "state": {}, "meta": Evil(marker)}, evil)
    cut = tmp_path / "cut.pt"
    cut.write_bytes(WEIGHTS_PATH.read_bytes()[:5000])
    detector = tmp_path / "detector.pt"
    detector.write_bytes(WEIGHTS_PATH.with_name("keypoint_net.pt").read_bytes())
    good = tmp_path / "good.pt"
    new_regressor().save(good)
    blob = torch.load(good, weights_only=True)
    arms = tmp_path / "arms.pt"
    torch.save(blob | {"state": {"psm3": blob["state"]["psm1"]}}, arms)
    nopose = tmp_path / "nopose.pt"
    torch.save(blob | {"meta": {"jaw": 0.8}}, nopose)
    shapes = tmp_path / "shapes.pt"
    torch.save(blob | {"state": blob["state"] | {"psm2": {"x": torch.zeros(1)}}}, shapes)
    cases = {
        evil: "refused",
        cut: "not a readable",
        detector: "format 'suture_bt.keypoint_net.v1'",
        arms: "arms",
        nopose: "poses/jaw",
        shapes: "do not match OffsetMLP",
    }
    for path, reason in cases.items():
        assert_refused(OffsetRegressor.load, path, reason, "suture-bt train calibration")
    assert not marker.exists()
