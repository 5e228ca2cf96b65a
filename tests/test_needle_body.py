"""Needle body: rests on the tissue when dropped, follows its holder, stays frozen when inserted."""

import numpy as np
import pybullet as p
import pytest

from suture_bt.geometry.needle import NeedleModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z, PhantomModel
from suture_bt.sim.needle_body import NeedleBody
from suture_bt.sim.phantom_body import PhantomBody
from suture_bt.transforms import make_transform, rotation_angle, rpy_to_matrix

MODEL = NeedleModel()
START = (-0.0208, 0.0562, 0.0717)  # SRC initial needle position (DESIGN.md §5)


@pytest.fixture
def client():
    c = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=c)
    p.setTimeStep(1e-3, physicsClientId=c)
    yield c
    p.disconnect(c)


def step(c, n):
    for _ in range(n):
        p.stepSimulation(physicsClientId=c)


def holder(c) -> int:
    """A kinematic 'arm': fixed base and one revolute link whose COM is off its link frame."""
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.002] * 3, physicsClientId=c)
    return p.createMultiBody(
        baseMass=0.0,
        basePosition=[0.0, 0.0, 0.12],
        linkMasses=[0.05],
        linkCollisionShapeIndices=[col],
        linkVisualShapeIndices=[-1],
        linkPositions=[[0.0, 0.0, -0.01]],
        linkOrientations=[[0, 0, 0, 1]],
        linkInertialFramePositions=[[0.003, -0.002, 0.004]],
        linkInertialFrameOrientations=[list(p.getQuaternionFromEuler([0.2, 0.1, 0.3]))],
        linkParentIndices=[0],
        linkJointTypes=[p.JOINT_REVOLUTE],
        linkJointAxis=[[1, 0, 0]],
        physicsClientId=c,
    )


def link_pose(c, body, link) -> np.ndarray:
    s = p.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=c)
    return make_transform(np.array(p.getMatrixFromQuaternion(s[5])).reshape(3, 3), s[4])


def test_dropped_needle_comes_to_rest_on_tissue(client):
    phantom = PhantomBody(client, PhantomModel())
    T0 = make_transform(rpy_to_matrix((0.4, -0.3, 0.8)), np.add(START, (0, 0, 0.02)))
    needle = NeedleBody(client, MODEL, T0, tissue_ids=(phantom.id,))
    assert needle.state == "free"
    step(client, 600)
    assert needle.pose()[2, 3] < T0[2, 3] - 0.015  # it fell
    for _ in range(30):  # rests within 3 s
        step(client, 100)
        if needle.is_resting():
            break
    assert needle.is_resting()
    T = needle.pose()
    pts = MODEL.centerline(64) @ T[:3, :3].T + T[:3, 3]
    # Lying flat on the tissue: every point of the wire one wire radius above the surface.
    np.testing.assert_allclose(pts[:, 2], TISSUE_TOP_Z + MODEL.wire_radius, atol=1e-4)
    step(client, 500)  # and it stays there
    np.testing.assert_allclose(needle.pose()[:3, 3], T[:3, 3], atol=5e-5)


def test_attached_needle_follows_parent_and_falls_when_released(client):
    arm = holder(client)
    T0 = make_transform(position=(0.0, 0.0, 0.10))
    needle = NeedleBody(client, MODEL, T0)
    T_link_needle = make_transform(rpy_to_matrix((0.3, 0.2, -0.5)), (0.001, 0.002, -0.008))
    needle.attach(arm, 0, T_link_needle)
    assert needle.held_by == (arm, 0) and needle.state == "held"
    np.testing.assert_allclose(needle.pose(), link_pose(client, arm, 0) @ T_link_needle, atol=1e-9)
    for k in range(1, 301):  # the arm moves kinematically (reset each step) for 0.3 s
        p.resetBasePositionAndOrientation(
            arm, [0.02 * k / 300, 0.0, 0.12], [0, 0, 0, 1], physicsClientId=client
        )
        p.resetJointState(arm, 0, 0.8 * k / 300, physicsClientId=client)
        step(client, 1)
        if k == 150:  # the constraint alone keeps it close ...
            lag = needle.pose()[:3, 3] - (link_pose(client, arm, 0) @ T_link_needle)[:3, 3]
            assert np.linalg.norm(lag) < 1e-3
        needle.update()  # ... and update() puts it exactly in the jaw
    expected = link_pose(client, arm, 0) @ T_link_needle
    T = needle.pose()
    assert np.linalg.norm(T[:3, 3] - expected[:3, 3]) < 1e-9
    assert rotation_angle(T[:3, :3], expected[:3, :3]) < 1e-8
    with pytest.raises(ValueError, match="T_link_needle"):
        needle.attach(arm, 0, np.eye(3))
    needle.detach()
    assert needle.held_by is None and needle.state == "free"
    with pytest.raises(ValueError, match="needle pose"):
        needle.set_pose(np.full((4, 4), np.nan))
    step(client, 200)
    assert needle.pose()[2, 3] < T[2, 3] - 0.1  # free fall for 0.2 s (no tissue here)


def test_released_inserted_needle_stays_frozen(client):
    phantom = PhantomBody(client, PhantomModel())
    entry = phantom.phantom.port("entry2")
    # Needle plane vertical through the entry port, tip 4 mm inside the tissue.
    R = entry.T[:3, :3] @ rpy_to_matrix((np.pi / 2, 0.0, 0.0))
    T_in = make_transform(R)
    tip_in_needle = MODEL.tip
    T_in[:3, 3] = entry.position - R @ tip_in_needle - 0.004 * entry.normal
    assert phantom.inserted(T_in)
    arm = holder(client)
    T_link = np.linalg.inv(link_pose(client, arm, 0)) @ T_in
    needle = NeedleBody(client, MODEL, T_in, tissue_ids=(phantom.id,))
    needle.attach(arm, 0, T_link)
    step(client, 10)
    needle.detach()
    assert phantom.inserted(needle.pose())
    needle.freeze()
    assert needle.state == "frozen"
    T = needle.pose()
    step(client, 1000)
    np.testing.assert_allclose(needle.pose(), T, atol=1e-6)
    needle.unfreeze()  # tissue lets go: no contact is forced while it is still inside
    assert needle.state == "free"
    step(client, 300)
    # It falls through the tissue (collisions stay off while inside) onto the floor below.
    assert needle.pose()[2, 3] < T[2, 3] - 0.005


def test_needle_released_against_the_tissue_is_lifted_out_not_let_through(client):
    # Held flat with its wire 0.3 mm into the tissue top (not stuck: its centre-line is above
    # the surface), then let go: it rests on the tissue instead of falling through it.
    phantom = PhantomBody(client, PhantomModel())
    T = make_transform(np.eye(3), (-0.03, 0.0, TISSUE_TOP_Z + MODEL.wire_radius - 0.0003))
    assert not phantom.inserted(T)
    arm = holder(client)
    needle = NeedleBody(client, MODEL, T, tissue_ids=(phantom.id,))
    needle.attach(arm, 0, np.linalg.inv(link_pose(client, arm, 0)) @ T)
    step(client, 10)
    needle.detach()
    step(client, 500)
    assert needle.state == "free" and needle.is_resting()
    assert abs(needle.pose()[2, 3] - T[2, 3]) < 0.001  # on the tissue top, not under it
