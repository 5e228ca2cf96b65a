"""The interfaces skills and algorithms talk to; the simulation (or a real dVRK) implements them."""

from suture_bt.interfaces.camera_model import CameraModel, StereoCameraModel
from suture_bt.interfaces.robot import (
    Clock,
    FrameLost,
    JawInterface,
    JointState,
    PSMInterface,
    StereoCameraInterface,
    StereoFrame,
    WorldInterface,
)

__all__ = [
    "CameraModel",
    "Clock",
    "FrameLost",
    "JawInterface",
    "JointState",
    "PSMInterface",
    "StereoCameraInterface",
    "StereoCameraModel",
    "StereoFrame",
    "WorldInterface",
]
