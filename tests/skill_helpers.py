"""Skill-test fakes: an arm whose measured joints stay at the scene's initial pose, and the
slice of a task context (camera model, phantom, needle, belief) the pose-choosing skills read."""

from types import SimpleNamespace

import numpy as np

from suture_bt.control import PIServo
from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.kinematics import forward_kinematics, inverse_kinematics
from suture_bt.planning import to_base
from suture_bt.sim.camera import stereo_model
from suture_bt.sim.world import psm_base_frame
from suture_bt.skills.context import ArmHandle
from suture_bt.skills.grasps import hand
from suture_bt.skills.presentation import candidate_poses
from suture_bt.transforms import pose_to_transform

#: The scene's initial joints (sim/default_scene.yaml).
INITIAL_JP = {
    "psm1": (0.4, -0.22, 0.139, 1.64, -0.37, 0.11),
    "psm2": (-0.4, -0.22, 0.139, -1.64, -0.37, -0.11),
}
CAMERA = SimpleNamespace(model=stereo_model(1920, 1080))
PHANTOMS = {
    "default": np.eye(4),
    "moved": pose_to_transform((0.03, -0.02, 0.0), (0.0, 0.0, 0.26)),
    "tilted": pose_to_transform((0.0, 0.01, 0.0), (0.2, 0.1, 0.0)),
}


class FakeArm:
    """Measured joints fixed at the scene's initial pose; servo commands are recorded."""

    def __init__(self, name: str):
        self.name = name
        self.q = np.array(INITIAL_JP[name])
        self.commands = []

    def base_frame(self) -> np.ndarray:
        return psm_base_frame(self.name)

    def measured_jp(self) -> np.ndarray:
        return self.q.copy()

    def servo_jp(self, jp) -> None:
        self.commands.append(np.asarray(jp))


def make_ctx(T_world_phantom=None):
    return SimpleNamespace(
        camera=CAMERA,
        phantom=PhantomModel(np.eye(4) if T_world_phantom is None else T_world_phantom),
        needle=NeedleModel(),
        belief=None,
    )


def make_arm(name: str = "psm2") -> ArmHandle:
    fake = FakeArm(name)
    return ArmHandle(name, fake, PIServo(fake))


#: The true offset (joints 1-3) in the presented-needle tests: a grid point of the bound.
TRUE_OFFSET = np.array([np.deg2rad(2.5), np.deg2rad(-2.5), 0.0025])


def presented(arm, ctx):
    """Joints (measured) of a presentation pose and the needle's true pose held there, for an
    arm whose measured joints read ``TRUE_OFFSET`` less than its true ones."""
    T = candidate_poses(ctx, arm, limit=1)[0]
    q = inverse_kinematics(to_base(T, arm.base_frame()), arm.servo.setpoint_jp())
    arm.arm.q = q.copy()
    arm.servo.reset()
    q_true = q.copy()
    q_true[:3] += TRUE_OFFSET
    T_grasp = hand(ctx.needle, np.deg2rad(150.0))
    return q, arm.base_frame() @ forward_kinematics(q_true) @ T_grasp
