"""PSM kinematics: modified-DH forward kinematics and the closed-form inverse (DESIGN.md §5)."""

from suture_bt.kinematics.ik import UnreachablePoseError, inverse_kinematics
from suture_bt.kinematics.psm import (
    JAW_LIMITS,
    JOINT_LIMITS,
    L_PITCH2YAW,
    L_RCC,
    L_TOOL,
    L_YAW2CTRLPNT,
    NUM_JOINTS,
    clip_to_limits,
    forward_kinematics,
    frame_transforms,
    limit_violations,
)

__all__ = [
    "JAW_LIMITS",
    "JOINT_LIMITS",
    "L_PITCH2YAW",
    "L_RCC",
    "L_TOOL",
    "L_YAW2CTRLPNT",
    "NUM_JOINTS",
    "UnreachablePoseError",
    "clip_to_limits",
    "forward_kinematics",
    "frame_transforms",
    "inverse_kinematics",
    "limit_violations",
]
