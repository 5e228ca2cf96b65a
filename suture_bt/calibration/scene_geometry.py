"""The default SRC scene's arm bases and endoscope (DESIGN.md §5), as a real system is told them.

Calibration poses are chosen and the offset regressor is trained for this geometry; at run
time ``calibrate`` uses the arm's ``base_frame()`` and the camera's own model, and refuses
(see ``calibrate.CalibrationFailed``) when they differ from these.
"""

from __future__ import annotations

import numpy as np

from suture_bt.interfaces import CameraModel, StereoCameraModel
from suture_bt.transforms import make_transform, pose_to_transform

#: PSM base (RCM) frames in the world.
PSM_BASES = {
    "psm1": pose_to_transform((0.100, 0.1346, 0.1350), (0.6981, -0.5236, -np.pi)),
    "psm2": pose_to_transform((-0.100, 0.1346, 0.1350), (0.6981, 0.5236, -np.pi)),
}
ARM_NAMES = tuple(PSM_BASES)
#: Endoscope frame (looks along −z, +y up); eyes ±2 mm along its x, 50 mm along its −z.
T_WORLD_ENDOSCOPE = pose_to_transform((0.0, 0.0963, 0.1671), (0.6981, 0.0, -np.pi))
EYE_HALF_BASELINE = 0.002
EYE_FORWARD = 0.05
FOV_Y = 1.2
#: The SRC camera resolution, in which keypoint pixels are expressed for the regressor.
REFERENCE_SIZE = (1920, 1080)
#: OpenGL-style (x right, y up, −z forward) to OpenCV (x right, y down, z forward).
_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def eye_pose(eye: str) -> np.ndarray:
    """T_world_cam (OpenCV convention) of the ``left`` (−x) or ``right`` (+x) eye."""
    if eye not in ("left", "right"):
        raise ValueError(f"eye must be 'left' or 'right', got {eye!r}")
    sx = -1.0 if eye == "left" else 1.0
    offset = make_transform(None, (sx * EYE_HALF_BASELINE, 0.0, -EYE_FORWARD))
    return T_WORLD_ENDOSCOPE @ offset @ _GL_TO_CV


def endoscope_model(width: int = REFERENCE_SIZE[0], height: int = REFERENCE_SIZE[1]):
    """The SRC stereo endoscope as a StereoCameraModel at the given resolution."""
    return StereoCameraModel(
        CameraModel.from_fov(width, height, FOV_Y, eye_pose("left")),
        CameraModel.from_fov(width, height, FOV_Y, eye_pose("right")),
    )
