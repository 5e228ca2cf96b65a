"""The pybullet PSM's link frames reproduce the numpy DH forward kinematics."""

import numpy as np
import pybullet as pb
import pytest

from suture_bt.kinematics import JOINT_LIMITS, frame_transforms
from suture_bt.sim.psm_body import LINK_JAWS, LINK_TIP, LINK_WRIST_YAW, PSMBody
from suture_bt.sim.world import psm_base_frame
from suture_bt.transforms import rotation_angle


@pytest.fixture
def client():
    c = pb.connect(pb.DIRECT)
    yield c
    pb.disconnect(physicsClientId=c)


@pytest.mark.parametrize("arm", ["psm1", "psm2"])
def test_link_frames_equal_dh_fk(client, arm, rng):
    T_base = psm_base_frame(arm)
    body = PSMBody(client, T_base)
    worst_p, worst_r = 0.0, 0.0
    for _ in range(150):
        q = rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
        body.set_joints(q, rng.uniform(0, 1.5))
        for k, F in enumerate(frame_transforms(q)):
            T = body.link_pose(k)
            expected = T_base @ F
            worst_p = max(worst_p, float(np.linalg.norm(T[:3, 3] - expected[:3, 3])))
            worst_r = max(worst_r, rotation_angle(T[:3, :3], expected[:3, :3]))
    assert worst_p < 1e-6
    assert worst_r < 1e-6


def test_jaws_open_symmetrically_about_the_yaw_axis(client):
    body = PSMBody(client, np.eye(4))
    q = np.array([0.2, -0.1, 0.12, 0.3, 0.2, -0.1])
    body.set_joints(q, 0.8)
    yaw = body.link_pose(LINK_WRIST_YAW)
    a, b = (body.link_pose(k) for k in LINK_JAWS)
    # Each blade is the yaw frame rotated by ±jaw/2 about the yaw axis (its z).
    assert rotation_angle(a[:3, :3], yaw[:3, :3]) == pytest.approx(0.4, abs=1e-6)
    assert rotation_angle(b[:3, :3], yaw[:3, :3]) == pytest.approx(0.4, abs=1e-6)
    assert np.allclose(a[:3, 2], yaw[:3, 2], atol=1e-6)
    assert rotation_angle(a[:3, :3], b[:3, :3]) == pytest.approx(0.8, abs=1e-6)
    # The tip link is the DH tip frame.
    assert np.allclose(body.link_pose(LINK_TIP), frame_transforms(q)[-1], atol=1e-6)
