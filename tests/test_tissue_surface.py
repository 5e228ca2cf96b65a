"""The phantom's tissue surface: flat top, the ridge through the ports, moved with the phantom."""

import numpy as np
import pytest

from suture_bt.geometry import PhantomModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.geometry.tissue_surface import (
    RIDGE_END_MARGIN,
    height_above_tissue,
    ridge_segments,
    solid_pieces,
    surface_height,
)
from suture_bt.transforms import pose_to_transform

POSES = {
    "default": np.eye(4),
    "moved": pose_to_transform((0.02, -0.01, 0.005), (0.05, -0.04, 0.3)),
}


@pytest.mark.parametrize("pose", sorted(POSES))
def test_every_port_lies_on_the_surface(pose):
    phantom = PhantomModel(POSES[pose])
    for port in phantom.ports():
        assert height_above_tissue(phantom, port.position[None])[0] == pytest.approx(0, abs=1e-9)


def test_the_ridge_crest_lies_between_the_flanks_above_the_ports():
    phantom = PhantomModel()
    entry, exit_ = phantom.pair(2)
    xs = np.linspace(entry.position[0], exit_.position[0], 41)
    pts = np.column_stack([xs, np.full_like(xs, entry.position[1]), np.zeros_like(xs)])
    h = surface_height(phantom, pts)
    crest = int(np.argmax(h))
    assert 0 < crest < len(xs) - 1
    assert h[crest] > entry.position[2] + 0.003  # about 4 mm above the ports


def test_away_from_the_ridge_the_surface_is_the_flat_top():
    phantom = PhantomModel()
    beyond = 0.044 + RIDGE_END_MARGIN + 0.01
    pts = np.array([[0.03, 0.0, 0.2], [-0.03, 0.02, 0.0], [0.0, beyond, 0.0]])
    np.testing.assert_allclose(surface_height(phantom, pts), TISSUE_TOP_Z)


def test_segments_cover_the_pairs_and_reach_past_the_outer_ones():
    segs = ridge_segments(PhantomModel())
    assert len(segs) == 4
    assert all(a[1] == pytest.approx(b[0]) for a, b in zip(segs, segs[1:], strict=False))
    ys = [0.5 * (e[1, 3] + x[1, 3]) for _, _, e, x in segs]
    assert segs[0][0] == pytest.approx(ys[0] - RIDGE_END_MARGIN)
    assert segs[-1][1] == pytest.approx(ys[-1] + RIDGE_END_MARGIN)


def test_a_raised_phantom_raises_the_surface():
    low, high = PhantomModel(), PhantomModel(pose_to_transform((0, 0, 0.01), (0, 0, 0)))
    p = np.array([[0.0, 0.02, 0.1]])
    assert height_above_tissue(low, p)[0] - height_above_tissue(high, p)[0] == pytest.approx(0.01)


def test_the_surface_matches_the_simulated_solid():
    """Points just above the surface are outside the simulated tissue, just below inside."""
    import pybullet as p

    from suture_bt.sim.phantom_body import PhantomBody

    cid = p.connect(p.DIRECT)
    try:
        phantom = PhantomModel(POSES["moved"])
        body = PhantomBody(cid, phantom)
        rng = np.random.default_rng(3)
        q = np.column_stack([rng.uniform(-0.04, 0.04, 300), rng.uniform(-0.05, 0.07, 300)])
        T = phantom.T_world_phantom
        world = np.column_stack([q, np.zeros(len(q))]) @ T[:3, :3].T + T[:3, 3]
        up = T[:3, 2]
        surface = world - height_above_tissue(phantom, world)[:, None] * up
        assert not body.inside_tissue(surface + 0.0003 * up).any()
        assert body.inside_tissue(surface - 0.0003 * up).all()
    finally:
        p.disconnect(cid)


@pytest.mark.parametrize("pose", sorted(POSES))
def test_the_solid_s_pieces_hold_exactly_the_points_under_the_surface(pose):
    """Inside a piece (below all its planes) ⇔ below the surface, over the block's footprint,
    wherever the phantom stands."""
    phantom = PhantomModel(POSES[pose])
    rng = np.random.default_rng(3)
    q = rng.uniform((-0.04, -0.05, 0.066), (0.04, 0.07, 0.08), (5000, 3))
    T = phantom.T_world_phantom
    world = q @ T[:3, :3].T + T[:3, 3]
    inside = np.zeros(len(q), bool)
    for piece in solid_pieces(phantom):
        P = np.array([p for p, _ in piece])
        N = np.array([n for _, n in piece])
        inside |= np.all(np.einsum("kqj,qj->kq", world[:, None] - P[None], N) < 0, axis=1)
    assert 0.2 < inside.mean() < 0.8
    np.testing.assert_array_equal(inside, height_above_tissue(phantom, world) < 0)
