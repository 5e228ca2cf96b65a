"""Parameterisation round trip and the exact needle rasteriser."""

import numpy as np
from perception_helpers import random_needle_pose, stereo

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_projection import (
    end_pixels,
    params_to_pose,
    phi_from_base_depth,
    pose_to_params,
    project_cam,
    rasterize_needle,
    transform_points,
)

MODEL = NeedleModel()


def test_params_round_trip_reproduces_pose():
    cam = stereo(640, 480).left
    rng = np.random.default_rng(0)
    poses = np.stack([random_needle_pose(rng) for _ in range(20)])
    x = pose_to_params(poses, cam, MODEL)
    back = params_to_pose(x, cam, MODEL)
    np.testing.assert_allclose(back, poses, atol=1e-9)
    ends = project_cam(cam, transform_points(poses[0], np.stack([MODEL.base, MODEL.tip])))
    np.testing.assert_allclose(x[0, :4], ends.ravel(), atol=1e-9)


def test_end_pixels_are_the_pinhole_images_of_base_and_tip():
    cam = stereo(640, 480).left
    T = np.eye(4)
    T[:3, 3] = (0.01, -0.02, 0.1)
    uv = end_pixels(cam, T, MODEL)
    for row, p in zip(uv, (MODEL.base + T[:3, 3], MODEL.tip + T[:3, 3]), strict=True):
        expected = (cam.fx * p[0] / p[2] + cam.cx, cam.fy * p[1] / p[2] + cam.cy)
        np.testing.assert_allclose(row, expected, atol=1e-9)


def test_phi_from_depth_puts_base_at_that_depth():
    cam = stereo(640, 480).left
    T = random_needle_pose(np.random.default_rng(3))
    x = pose_to_params(T, cam, MODEL)
    zb = transform_points(T, MODEL.base[None])[0, 2]
    phis = phi_from_base_depth(x[:2], x[2:4], zb, cam, MODEL)
    assert np.min(np.abs(phis - x[4])) < 1e-6


def test_infeasible_parameters_give_nan():
    cam = stereo(640, 480).left
    x = np.array([300.0, 200.0, 340.0, 210.0, -0.5, 0.0])
    assert np.isnan(params_to_pose(x, cam, MODEL)).all()


def test_rasterised_wire_width_matches_projected_radius():
    cam = stereo(1920, 1080).left
    T = np.eye(4)
    T[:3, 3] = (0.0, 0.0, 0.1)  # arc face-on at 100 mm
    m = rasterize_needle(cam, T, MODEL)
    # Column through the arc's top (angle 90°): the wire crosses it as a vertical run.
    u = int(round(cam.cx))
    rows = np.nonzero(m[:, u])[0]
    expected = 2 * cam.fy * MODEL.wire_radius / 0.1
    assert abs(len(rows) - expected) <= 1.5
    assert m.sum() > 0 and not m[0].any()
