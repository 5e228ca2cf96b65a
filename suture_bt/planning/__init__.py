"""Motion planning without pybullet: timing profiles, stepwise moves and needle-arc plans."""

from suture_bt.planning.needle_arc import (
    NeedleArc,
    NeedleArcError,
    TimedPoses,
    gripper_poses,
    in_base,
    plan_needle_arc,
)
from suture_bt.planning.timing import MinJerkProfile, TrapezoidalProfile, make_profile
from suture_bt.planning.trajectory import (
    CartesianMove,
    JointMove,
    MoveStatus,
    PoseSequenceMove,
    to_base,
)

__all__ = [
    "CartesianMove",
    "JointMove",
    "MinJerkProfile",
    "MoveStatus",
    "NeedleArc",
    "NeedleArcError",
    "PoseSequenceMove",
    "TimedPoses",
    "TrapezoidalProfile",
    "gripper_poses",
    "in_base",
    "make_profile",
    "plan_needle_arc",
    "to_base",
]
