"""Pinhole camera model (no distortion) shared by the simulator, perception and calibration.

Convention: OpenCV camera frame (x right, y down, z forward); pixel (u, v) = (column, row)
with integer values at pixel centres, so the principal point of a centred image is
((W-1)/2, (H-1)/2). ``T_world_cam`` maps camera-frame points to the world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.transforms import invert


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics and extrinsics of one eye."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    T_world_cam: np.ndarray

    @classmethod
    def from_fov(cls, width: int, height: int, fov_y: float, T_world_cam: np.ndarray):
        """A centred pinhole with vertical field of view ``fov_y`` (rad)."""
        f = height / (2.0 * np.tan(fov_y / 2.0))
        return cls(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0, T_world_cam)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def T_cam_world(self) -> np.ndarray:
        return invert(self.T_world_cam)

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """World points (N×3) in this camera's frame."""
        T = self.T_cam_world
        return np.asarray(points_world) @ T[:3, :3].T + T[:3, 3]

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N×2) of world points (N×3)."""
        pc = self.to_camera(np.atleast_2d(points_world))
        return np.stack(
            [self.fx * pc[:, 0] / pc[:, 2] + self.cx, self.fy * pc[:, 1] / pc[:, 2] + self.cy], 1
        )

    def scaled(self, width: int, height: int) -> CameraModel:
        """The same camera at another resolution (same field of view)."""
        sx, sy = width / self.width, height / self.height
        return CameraModel(
            width,
            height,
            self.fx * sx,
            self.fy * sy,
            (self.cx + 0.5) * sx - 0.5,
            (self.cy + 0.5) * sy - 0.5,
            self.T_world_cam,
        )


@dataclass(frozen=True)
class StereoCameraModel:
    """Left and right eyes of the endoscope."""

    left: CameraModel
    right: CameraModel

    @property
    def baseline(self) -> float:
        return float(np.linalg.norm(self.left.T_world_cam[:3, 3] - self.right.T_world_cam[:3, 3]))
