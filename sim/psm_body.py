"""A PSM as a pybullet multibody built from the modified-DH rows (DESIGN.md §5), primitives only.

The base link is the RCM frame at the arm's base pose. Each DH row Rx(α)·Tx(a)·Rz(θ)·Tz(d),
θ = q + θ0, is split into a fixed parent-to-joint transform Rx(α)·Tx(a)·Rz(θ0)·Tz(d0) and the
joint motion (Rz(q) for revolute joints, Tz(q) for the prismatic one, which commute with the
rest), so pybullet's link frame k equals DH frame k+1 exactly. Link 6 is the fixed tool tip;
links 7 and 8 are the two jaw blades, rotating ±jaw/2 about the wrist-yaw axis.

Links are kinematic: :meth:`PSMBody.set_joints` resets them from the servo model every physics
step, physics never moves the arm. The arm has visual shapes only (no collision shapes): the
needle is attached by the grasp logic, not held by contact.
"""

from __future__ import annotations

import numpy as np
import pybullet as pb

from suture_bt.kinematics.psm import L_PITCH2YAW, L_RCC, L_TOOL, L_YAW2CTRLPNT, dh_transform
from suture_bt.transforms import quat_xyzw

#: pybullet link indices (DH frame k+1 is link k).
LINK_SHAFT = 3  # frame 4: rolls with q4, carries the shaft
LINK_WRIST_PITCH = 4  # frame 5: the clevis
LINK_WRIST_YAW = 5  # frame 6: jaw pivot (wrist-yaw axis = its z)
LINK_TIP = 6  # frame 7: the tool tip (control point)
LINK_JAWS = (7, 8)  # jaw blade a (+jaw/2 about frame-6 z) and blade b (−jaw/2)
ARM_JOINTS = (0, 1, 2, 3, 4, 5)

#: Jaw blade geometry in its own link frame (frame 6 at jaw = 0): the blade runs along +y from
#: the yaw axis to ``JAW_LENGTH``; blades close onto the frame-6 y-z plane from −x (a) and +x (b).
JAW_LENGTH = 0.0125
JAW_THICKNESS = 0.0012
JAW_WIDTH = 0.0030
SHAFT_RADIUS = 0.0042
_H = np.pi / 2

# (α, a, θ0, d0, joint type) of DH rows 1..7.
_ROWS = (
    (_H, 0.0, _H, 0.0, pb.JOINT_REVOLUTE),
    (-_H, 0.0, -_H, 0.0, pb.JOINT_REVOLUTE),
    (_H, 0.0, 0.0, -L_RCC, pb.JOINT_PRISMATIC),
    (0.0, 0.0, 0.0, L_TOOL, pb.JOINT_REVOLUTE),
    (-_H, 0.0, -_H, 0.0, pb.JOINT_REVOLUTE),
    (-_H, L_PITCH2YAW, -_H, 0.0, pb.JOINT_REVOLUTE),
    (-_H, 0.0, _H, L_YAW2CTRLPNT, pb.JOINT_FIXED),
)


def _visual(client: int, shape: int, rgba, pos=(0, 0, 0), **kw) -> int:
    return pb.createVisualShape(
        shape, rgbaColor=rgba, visualFramePosition=list(pos), physicsClientId=client, **kw
    )


class PSMBody:
    """The pybullet body of one PSM; joint state set from outside each physics step."""

    def __init__(self, client: int, T_world_base: np.ndarray, q0=None, name: str = "psm"):
        self.client = client
        self.name = name
        self.T_world_base = np.array(T_world_base, dtype=float)
        grey, dark, steel = [0.55, 0.55, 0.58, 1], [0.25, 0.25, 0.27, 1], [0.75, 0.75, 0.78, 1]
        shaft = _visual(
            client,
            pb.GEOM_CYLINDER,
            dark,
            (0, 0, -(L_TOOL - 0.006) / 2 - 0.006),
            radius=SHAFT_RADIUS,
            length=L_TOOL - 0.006,
        )
        clevis = _visual(
            client, pb.GEOM_BOX, grey, (L_PITCH2YAW / 2, 0, 0), halfExtents=[0.0065, 0.0022, 0.003]
        )
        jaw_a = _visual(
            client,
            pb.GEOM_BOX,
            steel,
            (-JAW_THICKNESS / 2, JAW_LENGTH / 2, 0),
            halfExtents=[JAW_THICKNESS / 2, JAW_LENGTH / 2, JAW_WIDTH / 2],
        )
        jaw_b = _visual(
            client,
            pb.GEOM_BOX,
            steel,
            (JAW_THICKNESS / 2, JAW_LENGTH / 2, 0),
            halfExtents=[JAW_THICKNESS / 2, JAW_LENGTH / 2, JAW_WIDTH / 2],
        )
        visuals = [-1, -1, -1, shaft, clevis, -1, -1, jaw_a, jaw_b]
        positions, orientations, types, parents = [], [], [], []
        for k, (alpha, a, th0, d0, jtype) in enumerate(_ROWS):
            T = dh_transform(alpha, a, th0, d0)
            positions.append(T[:3, 3].tolist())
            orientations.append(quat_xyzw(T[:3, :3]).tolist())
            types.append(jtype)
            parents.append(k)  # pybullet: 0 = base, k = link k-1
        for _ in LINK_JAWS:
            positions.append([0.0, 0.0, 0.0])
            orientations.append([0.0, 0.0, 0.0, 1.0])
            types.append(pb.JOINT_REVOLUTE)
            parents.append(LINK_WRIST_YAW + 1)
        n = len(types)
        self.body = pb.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=-1,
            baseVisualShapeIndex=-1,
            basePosition=self.T_world_base[:3, 3].tolist(),
            baseOrientation=quat_xyzw(self.T_world_base[:3, :3]).tolist(),
            linkMasses=[0.01] * n,
            linkCollisionShapeIndices=[-1] * n,
            linkVisualShapeIndices=visuals,
            linkPositions=positions,
            linkOrientations=orientations,
            linkInertialFramePositions=[[0.0, 0.0, 0.0]] * n,
            linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * n,
            linkParentIndices=parents,
            linkJointTypes=types,
            linkJointAxis=[[0.0, 0.0, 1.0]] * n,
            physicsClientId=client,
        )
        # No motors, no damping: the arm is positioned by resets only.
        movable = list(ARM_JOINTS) + list(LINK_JAWS)
        pb.setJointMotorControlArray(
            self.body,
            movable,
            pb.VELOCITY_CONTROL,
            forces=[0.0] * len(movable),
            physicsClientId=client,
        )
        self._indices = movable
        self.q = np.zeros(6)
        self.jaw = 0.0
        self.set_joints(np.zeros(6) if q0 is None else q0, 0.0)

    def set_joints(self, q, jaw: float) -> None:
        """Reset the six arm joints to q and the jaw blades to ±jaw/2 (kinematic update)."""
        self.q = np.array(q, dtype=float)
        self.jaw = float(jaw)
        values = [[v] for v in self.q] + [[self.jaw / 2], [-self.jaw / 2]]
        pb.resetJointStatesMultiDof(
            self.body,
            self._indices,
            targetValues=values,
            targetVelocities=[[0.0]] * len(values),
            physicsClientId=self.client,
        )

    def link_pose(self, link: int) -> np.ndarray:
        """World transform of a link frame (as pybullet has it now)."""
        state = pb.getLinkState(
            self.body, link, computeForwardKinematics=True, physicsClientId=self.client
        )
        T = np.eye(4)
        T[:3, :3] = np.reshape(pb.getMatrixFromQuaternion(state[5]), (3, 3))
        T[:3, 3] = state[4]
        return T

    def tip_pose(self) -> np.ndarray:
        """World pose of the tool tip (pybullet's link frame)."""
        return self.link_pose(LINK_TIP)
