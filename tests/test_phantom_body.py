"""Phantom body: geometry at the SRC ports, segmentation, and the crossing/strain recorder."""

import numpy as np
import pybullet as p
import pytest

from suture_bt.geometry.needle import NeedleModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z, PhantomModel
from suture_bt.sim.camera import StereoEndoscope
from suture_bt.sim.needle_body import NeedleBody
from suture_bt.sim.phantom_body import PhantomBody
from suture_bt.sim.phantom_build import FLOOR_DEPTH, FLOOR_HALF_THICKNESS
from suture_bt.transforms import make_transform, pose_to_transform

MODEL = NeedleModel()


@pytest.fixture
def client():
    c = p.connect(p.DIRECT)
    yield c
    p.disconnect(c)


def ideal_throw(phantom: PhantomModel, pair: int, psi: float, shift=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Needle pose on the circle through entry/exit of ``pair``, rotated by ``psi`` in its plane.

    The plane is the ports' common vertical plane; decreasing ``psi`` drives the tip forward
    (into the entry, under the ridge, out of the exit). Built in the phantom frame.
    """
    entry, exit_ = (phantom.ports_in_phantom[2 * (pair - 1) + k].T[:3, 3] for k in (0, 1))
    mid, chord = (entry + exit_) / 2, exit_ - entry
    up = np.cross(chord, [0.0, 1.0, 0.0])
    up /= np.linalg.norm(up) * np.sign(up[2])
    centre = mid + up * np.sqrt(MODEL.radius**2 - (np.linalg.norm(chord) / 2) ** 2)
    x, y, z = np.eye(3)
    R_plane = np.stack([x, -z, y], 1)  # needle angle a ↔ world point c + r(cos a x − sin a z)
    c, s = np.cos(psi), np.sin(psi)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return phantom.T_world_phantom @ make_transform(R_plane @ Rz, centre + np.asarray(shift))


def port_psi(phantom, name, pair=1):
    """Needle rotation that puts the tip exactly on a port (phantom frame)."""
    port = next(q for q in phantom.ports_in_phantom if q.name == name)
    T0 = ideal_throw(PhantomModel(ports_in_phantom=phantom.ports_in_phantom), pair, 0.0)
    q = np.linalg.inv(T0) @ np.r_[port.T[:3, 3], 1.0]
    return np.arctan2(q[1], q[0]) - MODEL.tip_angle


@pytest.mark.parametrize(
    "T_world_phantom",
    [np.eye(4), pose_to_transform((0.01, -0.02, 0.005), (0.1, -0.05, 0.7))],
    ids=["src", "moved"],
)
def test_scripted_throw_records_src_crossings(client, T_world_phantom):
    phantom = PhantomModel(T_world_phantom)
    body = PhantomBody(client, phantom)
    psi_entry, psi_exit = port_psi(phantom, "entry1"), port_psi(phantom, "exit1")
    assert psi_exit < psi_entry
    out = 0.006  # drive on until the tip is 6 mm (chord) past the exit
    psi_end = psi_exit - 2 * np.arcsin(out / (2 * MODEL.radius))
    psis = np.linspace(psi_entry + 0.3, psi_end, 400)
    engaged_seen = set()
    for k, psi in enumerate(psis):
        T = ideal_throw(phantom, 1, psi)
        body.update(T, 0.01 * k)
        engaged_seen |= set(body.strain)
        if psi < psi_exit - 0.05:
            for s in body.strain.values():
                assert s.circle < 1e-6 and s.plane < 1e-6  # ideal path: no strain
    names = [(c.port, c.src_direction) for c in body.crossings]
    assert names == [("entry1", True), ("exit1", True)]
    entry, exit_ = body.crossings
    assert entry.inward and not exit_.inward
    assert entry.lateral < 2e-5 and exit_.lateral < 2e-5
    assert exit_.tip_out == pytest.approx(out, abs=2e-5)
    assert entry.t < exit_.t
    assert {"entry1", "exit1"} <= engaged_seen
    assert body.inserted(ideal_throw(phantom, 1, (psi_entry + psi_exit) / 2))
    assert not body.inserted(ideal_throw(phantom, 1, psi_entry + 0.3))


def test_offset_throw_lateral_distance_strain_and_backing_out(client):
    phantom = PhantomModel()
    body = PhantomBody(client, phantom)
    shift = (0.0, 0.001, 0.0)  # 1 mm beside the ports, out of the ports' plane
    psi_entry, psi_exit = port_psi(phantom, "entry2", 2), port_psi(phantom, "exit2", 2)
    forward = np.linspace(psi_entry + 0.2, (psi_entry + psi_exit) / 2, 100)
    for k, psi in enumerate(np.r_[forward, forward[::-1]]):
        body.update(ideal_throw(phantom, 2, psi, shift), 0.01 * k)
        if k == len(forward) - 1:
            s = body.strain["entry2"]
            assert s.plane == pytest.approx(0.001, abs=1e-9)
            assert s.circle == pytest.approx(0.001, abs=1e-9)
    assert [(c.port, c.inward) for c in body.crossings] == [("entry2", True), ("entry2", False)]
    assert body.crossings[0].lateral == pytest.approx(0.001, abs=2e-5)
    assert not body.crossings[1].src_direction  # backing out of an entry is not scored
    assert body.max_strain["entry2"].circle == pytest.approx(0.001, abs=1e-9)


def test_geometry_and_segmentation(client):
    phantom = PhantomModel()
    body = PhantomBody(client, phantom)
    # Every port lies on the surface: just above it is outside, just below is tissue.
    for port in phantom.ports():
        out, into = port.position + 2e-4 * port.normal, port.position - 2e-4 * port.normal
        assert body.inside_tissue(np.stack([out, into])).tolist() == [False, True]
    assert body.inside_tissue(np.array([[0.0, 0.0, TISSUE_TOP_Z - 0.001]]))[0]
    assert not body.inside_tissue(np.array([[-0.02, 0.0, TISSUE_TOP_Z + 0.001]]))[0]
    # The floor is solid: just under its top face counts, just above it does not.
    floor_top = TISSUE_TOP_Z - FLOOR_DEPTH + FLOOR_HALF_THICKNESS
    under, over = [0.05, 0.0, floor_top - 1e-4], [0.05, 0.0, floor_top + 1e-4]
    assert body.below_floor(np.array([under, over])).tolist() == [True, False]
    cam = StereoEndoscope(client, 640, 480)
    # A needle above the tissue and a box standing in for an arm, all in view.
    L = cam.model.left
    T_n = L.T_world_cam @ make_transform(position=(0.004, 0.0, 0.06))
    needle = NeedleBody(client, MODEL, T_n)
    box = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.002] * 3, physicsClientId=client)
    arm_pos = (L.T_world_cam @ np.array([-0.01, -0.008, 0.05, 1.0]))[:3]
    arm = p.createMultiBody(0, -1, box, list(arm_pos), physicsClientId=client)
    r = cam.render("left")
    ids = r.body_ids
    for body_id, point in ((needle.id, T_n[:3, :3] @ MODEL.point_at(2.0) + T_n[:3, 3]),
                           (arm, arm_pos)):  # fmt: skip
        u, v = np.rint(L.project(point)[0]).astype(int)
        assert ids[v, u] == body_id
    assert r.mask(body.id).sum() > 0.3 * ids.size  # tissue fills much of the view
    assert (ids == body.floor_id).any() and not (ids == -1).any()  # the floor is background
    mark = phantom.port("entry3")
    u, v = np.rint(L.project(mark.position)[0]).astype(int)
    assert r.link_ids[v, u] == body.mark_links["entry3"] and ids[v, u] == body.id
    assert r.rgb[v, u].max() < 80  # dark square
    u, v = np.rint(L.project(mark.position + 0.004 * mark.T[:3, 0])[0]).astype(int)
    assert r.link_ids[v, u] in body.slab_links and r.rgb[v, u, 0] > 120  # pink flank
