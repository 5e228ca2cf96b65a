"""Keypoint CNN plumbing: window geometry, box averaging, patches, sub-pixel decoding, shapes."""

import numpy as np
import pytest
import torch
from weights_helpers import Evil, assert_refused

from suture_bt.calibration.keypoint_net import (
    INPUT_SIZE,
    PATCH,
    WEIGHTS_PATH,
    FineNet,
    KeypointDetector,
    KeypointNet,
    box_average,
    coarse_to_window,
    cut_patches,
    extract_window,
    patch_origin,
    soft_argmax,
    to_input,
    window_around,
    window_to_coarse,
)
from suture_bt.calibration.scene_geometry import endoscope_model


def test_window_maps_image_points_and_its_camera_agrees():
    cam = endoscope_model().left
    win = window_around((700.3, 400.8), cam)
    assert win.scale == pytest.approx(0.25)
    p = np.array([[650.2, 420.7], [10.0, 5.0]])
    np.testing.assert_allclose(win.to_image(win.to_window(p)), p)
    wc = win.camera(cam)
    X = cam.T_world_cam[:3, :3] @ np.array([0.01, 0.02, 0.08]) + cam.T_world_cam[:3, 3]
    np.testing.assert_allclose(wc.project(X)[0], win.to_window(cam.project(X)[0]), atol=1e-9)
    # the window is centred on the requested point (to a pixel edge)
    np.testing.assert_allclose(
        win.to_window(np.array([700.3, 400.8])), INPUT_SIZE / 2 - 0.5, atol=0.2
    )


def test_extract_window_box_averages_and_pads_with_black():
    cam = endoscope_model(1920, 1080).left
    img = np.zeros((1080, 1920, 3), np.uint8)
    win = window_around((801.5, 501.5), cam)
    r, c = int(win.v0) + 4 * 30, int(win.u0) + 4 * 70
    img[r : r + 4, c : c + 4] = 200  # a 4×4 block = one window pixel
    w = extract_window(img, win)
    assert w[30, 70].tolist() == [200, 200, 200]
    np.testing.assert_allclose(win.to_window(np.array([c + 1.5, r + 1.5])), [70, 30])
    assert w.sum() == 200 * 3
    corner = extract_window(np.full_like(img, 90), window_around((0.0, 0.0), cam))
    assert corner[0, 0].tolist() == [0, 0, 0] and corner[-1, -1].tolist() == [90, 90, 90]


def test_box_average_and_coarse_coordinates():
    x = np.arange(16, dtype=np.uint8).reshape(1, 4, 4, 1).repeat(3, -1)
    y = box_average(x, 2)
    assert y.shape == (1, 2, 2, 3) and y[0, 0, 0, 0] == np.rint((0 + 1 + 4 + 5) / 4)
    uv = np.array([37.25, 101.5])
    np.testing.assert_allclose(coarse_to_window(window_to_coarse(uv)), uv)


def test_patches_are_centred_and_padded():
    w = np.zeros((INPUT_SIZE, INPUT_SIZE, 3), np.uint8)
    w[100, 50] = 255
    o = patch_origin(np.array([[50.0, 100.0]]))
    p = cut_patches(w, o)
    assert p.shape == (1, PATCH, PATCH, 3)
    assert p[0, PATCH // 2, PATCH // 2, 0] == 255 or p[0, PATCH // 2 - 1, PATCH // 2 - 1, 0] == 255
    edge = cut_patches(w, np.array([[-20, -20]]))
    assert edge.shape == (1, PATCH, PATCH, 3)


def test_soft_argmax_is_sub_pixel():
    h = w = 32
    vv, uu = np.mgrid[0:h, 0:w]
    u0, v0 = 12.3, 20.6
    logits = -((uu - u0) ** 2 + (vv - v0) ** 2) / (2 * 1.0**2)
    uv, peak = soft_argmax(torch.as_tensor(logits)[None, None].float())
    np.testing.assert_allclose(uv[0, 0], [u0, v0], atol=0.02)
    assert peak[0, 0] > 0.95


def test_networks_output_shapes_and_input_normalisation():
    x = np.random.default_rng(0).integers(0, 255, (2, 64, 64, 3), dtype=np.uint8)
    t = to_input(x)
    assert t.shape == (2, 3, 64, 64)
    np.testing.assert_allclose(t.mean(dim=(1, 2, 3)).numpy(), 0, atol=1e-5)
    # brightness ×2 (without clipping) leaves the normalised input unchanged
    np.testing.assert_allclose(to_input(x // 2).numpy(), to_input((x // 2) * 2).numpy(), atol=1e-4)
    with torch.no_grad():
        assert KeypointNet()(t).shape == (2, 4, 32, 32)
        assert FineNet()(to_input(x[:, :PATCH, :PATCH])).shape == (2, 4, PATCH, PATCH)


def _detector(seed: int = 0) -> KeypointDetector:
    torch.manual_seed(seed)
    meta = {"coarse_width": 4, "fine_width": 4, "validation_px": np.array([0.5, 0.25])}
    return KeypointDetector(KeypointNet(4).eval(), FineNet(4).eval(), meta)


def test_save_load_round_trip_keeps_detections_and_plain_meta(tmp_path):
    det = _detector()
    path = tmp_path / "kp.pt"
    det.save(path)
    back = KeypointDetector.load(path)
    assert back.meta["validation_px"] == [0.5, 0.25] and back.coarse.stem[0][0].out_channels == 4
    w = np.random.default_rng(3).integers(0, 255, (2, INPUT_SIZE, INPUT_SIZE, 3), dtype=np.uint8)
    kp0, c0 = det.detect_in_windows(w)
    kp1, c1 = back.detect_in_windows(w)
    np.testing.assert_array_equal(kp0, kp1)
    np.testing.assert_array_equal(c0, c1)


def test_shipped_weights_load_data_only():
    det = KeypointDetector.load()
    assert det.meta["coarse_width"] == 8 and len(det.meta["validation_px"]["mean"]) == 4
    blob = torch.load(WEIGHTS_PATH, map_location="cpu", weights_only=True)
    assert blob["format"] == "suture_bt.keypoint_net.v1"


def test_bad_weights_files_raise_one_line_errors(tmp_path):
    marker = tmp_path / "ran"
    evil = tmp_path / "evil.pt"
    torch.save({"format": "suture_bt.keypoint_net.v1", "state": Evil(marker), "meta": {}}, evil)
    text = tmp_path / "text.pt"
    text.write_text("hello\n")
    other = tmp_path / "other.pt"
    torch.save({"state": {}, "meta": {}}, other)  # the old untagged layout
    wrong = tmp_path / "wrong.pt"
    _detector().save(wrong)
    blob = torch.load(wrong, weights_only=True)
    blob["meta"]["fine_width"] = 6
    torch.save(blob, wrong)
    cases = {evil: "refused", text: "not a readable", other: "not a suture_bt.keypoint_net.v1"}
    cases[wrong] = "do not match FineNet"
    for path, reason in cases.items():
        assert_refused(KeypointDetector.load, path, reason, "suture-bt train calibration")
    assert not marker.exists()
    with pytest.raises(FileNotFoundError, match="suture-bt train calibration"):
        KeypointDetector.load(tmp_path / "missing.pt")
