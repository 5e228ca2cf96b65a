"""Offset regressor: MLP shapes, standard scaling, pixel rescaling and weight round trip."""

import numpy as np
import pytest
import torch

from suture_bt.calibration.calibration_pose import CALIBRATION_POSES
from suture_bt.calibration.offset_regressor import (
    HIDDEN,
    NUM_INPUTS,
    OffsetMLP,
    OffsetRegressor,
    new_regressor,
    regressor_features,
    to_reference_pixels,
)


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
    reg.meta["poses"]["psm1"] = [0.0] * 6
    reg.save(path)
    with pytest.raises(ValueError, match="another calibration pose"):
        OffsetRegressor.load(path)
    with pytest.raises(FileNotFoundError, match="suture-bt train calibration"):
        OffsetRegressor.load(tmp_path / "missing.pt")
