"""Pinhole model: DESIGN.md focal lengths, centred principal point, projection and scaling."""

import numpy as np

from suture_bt.interfaces import CameraModel


def test_focal_length_from_fov_matches_design():
    assert abs(CameraModel.from_fov(1920, 1080, 1.2, np.eye(4)).fx - 789.3) < 0.1
    assert abs(CameraModel.from_fov(640, 480, 1.2, np.eye(4)).fy - 350.8) < 0.1


def test_projection_of_the_optical_axis_hits_the_image_centre():
    cam = CameraModel.from_fov(640, 480, 1.2, np.eye(4))
    np.testing.assert_allclose(cam.project([[0, 0, 1.0]]), [[319.5, 239.5]])
    u = cam.project([[0.1, -0.05, 1.0]])[0]
    np.testing.assert_allclose(u, [319.5 + 0.1 * cam.fx, 239.5 - 0.05 * cam.fy])


def test_scaled_camera_sees_the_same_ray_at_the_same_relative_pixel():
    cam = CameraModel.from_fov(1920, 1080, 1.2, np.eye(4))
    small = cam.scaled(640, 360)
    p = np.array([[0.02, 0.01, 0.1]])
    np.testing.assert_allclose((small.project(p) + 0.5) * 3, cam.project(p) + 0.5, atol=1e-9)
