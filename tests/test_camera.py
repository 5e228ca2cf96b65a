"""Stereo endoscope: geometry per DESIGN.md §5 and images truly at the claimed resolution."""

import numpy as np
import pybullet as p
import pytest

from suture_bt.geometry.needle import NeedleModel
from suture_bt.interfaces import StereoCameraInterface
from suture_bt.sim.camera import StereoEndoscope, default_camera_frame, stereo_model
from suture_bt.sim.needle_body import NeedleBody
from suture_bt.transforms import make_transform, rpy_to_matrix


@pytest.fixture
def client():
    c = p.connect(p.DIRECT)
    p.setGravity(0, 0, 0, physicsClientId=c)
    yield c
    p.disconnect(c)


def exact_silhouette(cam, model: NeedleModel, T_world_needle, n=2000) -> np.ndarray:
    """Pixels whose centre ray passes within the wire radius of the needle centre-line."""
    pts = (T_world_needle[:3, :3] @ model.centerline(n).T).T + T_world_needle[:3, 3]
    P = cam.to_camera(pts)
    uv = cam.project(pts)
    m = int(np.ceil(cam.fx * model.wire_radius / P[:, 2].min())) + 3
    u0, v0 = np.maximum(np.floor(uv.min(0)).astype(int) - m, 0)
    u1, v1 = np.minimum(np.ceil(uv.max(0)).astype(int) + m, [cam.width - 1, cam.height - 1])
    uu, vv = np.meshgrid(np.arange(u0, u1 + 1), np.arange(v0, v1 + 1))
    d = np.stack([(uu - cam.cx) / cam.fx, (vv - cam.cy) / cam.fy, np.ones_like(uu, float)], -1)
    d = d.reshape(-1, 3) / np.linalg.norm(d.reshape(-1, 3), axis=1, keepdims=True)
    inside = np.zeros(len(d), bool)
    p2 = (P**2).sum(1)
    for s in range(0, len(d), 8192):
        proj = d[s : s + 8192] @ P.T
        inside[s : s + 8192] = (p2[None] - proj**2).min(1) <= model.wire_radius**2
    mask = np.zeros((cam.height, cam.width), bool)
    mask[v0 : v1 + 1, u0 : u1 + 1] = inside.reshape(uu.shape)
    return mask


def test_model_matches_design():
    st = stereo_model(1920, 1080)
    L, R = st.left, st.right
    assert L.fx == pytest.approx(789.3, abs=0.05) and L.fy == L.fx
    assert (L.cx, L.cy) == (959.5, 539.5)
    assert stereo_model(640, 480).left.fx == pytest.approx(350.8, abs=0.05)
    assert st.baseline == pytest.approx(0.004)
    # Eyes 50 mm along the camera frame's −z, ±2 mm along its x; both look along its −z.
    Tcf = default_camera_frame()
    for cam, side in ((L, -1), (R, 1)):
        local = np.linalg.inv(Tcf) @ cam.T_world_cam
        np.testing.assert_allclose(local[:3, 3], [side * 0.002, 0, -0.05], atol=1e-12)
        np.testing.assert_allclose(local[:3, 2], [0, 0, -1], atol=1e-12)  # forward = −z
        np.testing.assert_allclose(local[:3, 1], [0, -1, 0], atol=1e-12)  # down = −y
    # A point in front of the cameras has positive disparity (left eye is on the left).
    X = L.T_world_cam @ np.array([0.003, 0.002, 0.1, 1.0])
    assert L.project(X[:3])[0, 0] - R.project(X[:3])[0, 0] == pytest.approx(
        L.fx * 0.004 / 0.1, rel=1e-9
    )
    # The SRC ports (54-100 mm away) are in view.
    port = np.array([-0.00374, 0.04419, 0.075])
    uv = L.project(port)[0]
    assert 0 < uv[0] < 1920 and 0 < uv[1] < 1080
    with pytest.raises(ValueError, match="resolution"):
        stereo_model(0, 480)
    # A moved endoscope keeps the eyes' offsets in its frame.
    T_moved = make_transform(rpy_to_matrix((0.1, 0.2, 0.3)), (0.01, 0.02, 0.2))
    moved = stereo_model(640, 480, T_moved).left
    np.testing.assert_allclose(
        np.linalg.inv(T_moved) @ moved.T_world_cam, np.linalg.inv(Tcf) @ L.T_world_cam, atol=1e-12
    )


@pytest.mark.parametrize(
    "size, renderer", [((1920, 1080), "egl"), ((640, 480), "egl"), ((640, 480), "tiny")]
)
def test_rendered_needle_is_exact_projection(client, size, renderer, monkeypatch):
    if renderer == "tiny":  # the fallback, compensated for its half-pixel offset
        monkeypatch.setenv("SUTURE_BT_RENDERER", "tiny")
    cam = StereoEndoscope(client, *size)
    assert cam.renderer == renderer
    model = NeedleModel()
    L = cam.model.left
    # Needle 95 mm in front of the left eye, tilted, as during localisation.
    T = L.T_world_cam @ make_transform(rpy_to_matrix((0.6, -0.4, 0.9)), (0.004, -0.003, 0.095))
    needle = NeedleBody(client, model, T)
    r = cam.render("left")
    assert r.rgb.shape == (size[1], size[0], 3) and r.rgb.dtype == np.uint8
    rendered = r.mask(needle.id)
    exact = exact_silhouette(L, model, T)
    iou = (rendered & exact).sum() / (rendered | exact).sum()
    assert iou >= 0.9, iou
    c_r = np.argwhere(rendered).mean(0)
    c_e = np.argwhere(exact).mean(0)
    assert np.linalg.norm(c_r - c_e) < 0.3
    # The depth buffer is metric: needle pixels sit at the needle's depth.
    z = L.to_camera(T[:3, 3][None])[0, 2]
    assert np.all(np.abs(r.depth[rendered] - z) < 0.012)


def test_capture_applies_sensor_model(client):
    cam = StereoEndoscope(client, 320, 240, noise_std=4.0, brightness=0.5)
    assert isinstance(cam, StereoCameraInterface)
    cam.set_clock(lambda: 1.25)
    clean = cam.render("left", with_segmentation=False).rgb.astype(float)
    frame = cam.capture()
    assert frame.stamp == 1.25 and cam.capture(stamp=2.0).stamp == 2.0
    assert frame.left.shape == frame.right.shape == (240, 320, 3)
    assert frame.left.dtype == np.uint8
    resid = frame.left.astype(float) - 0.5 * clean
    assert abs(resid.mean()) < 0.5 and resid.std() == pytest.approx(4.0, rel=0.15)
    with pytest.raises(ValueError):
        StereoEndoscope(client, 320, 240, noise_std=-1)


def test_light_direction_is_a_unit_vector_tilted_from_overhead():
    from suture_bt.sim.camera import light_direction

    d = np.array(light_direction(30.0, 90.0))
    assert np.isclose(np.linalg.norm(d), 1.0)
    assert np.isclose(np.degrees(np.arccos(d[2])), 30.0)
    assert np.isclose(d[0], 0.0, atol=1e-12) and d[1] > 0
    assert np.allclose(light_direction(0.0, 123.0), (0.0, 0.0, 1.0))
