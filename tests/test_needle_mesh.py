"""Needle mesh: a closed, outward-facing tube of the true wire radius with rounded ends."""

from collections import Counter

import numpy as np

from suture_bt.geometry.needle import NeedleModel
from suture_bt.sim.needle_mesh import (
    BAND_LENGTH,
    N_AROUND,
    band_vertices,
    needle_mesh_arrays,
    write_needle_obj,
)

MODEL = NeedleModel()


def centreline_distance(points: np.ndarray, model: NeedleModel) -> np.ndarray:
    """Distance of points (needle frame) to the arc's centre-line (with its end points)."""
    a = np.linspace(model.base_angle, model.tip_angle, 4001)
    c = model.point_at(a)
    return np.sqrt(((points[:, None, :] - c[None]) ** 2).sum(-1)).min(1)


def test_mesh_is_closed_outward_tube_of_true_radius():
    V, N, F = needle_mesh_arrays(MODEL)
    edges = Counter()
    for tri in F:
        for u, v in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            edges[(min(u, v), max(u, v))] += 1
    assert set(edges.values()) == {2}  # watertight
    volume = np.einsum("ij,ij->i", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])).sum() / 6
    r = MODEL.wire_radius
    assert volume > 0  # outward winding
    np.testing.assert_allclose(
        volume, np.pi * r**2 * MODEL.length + 4 / 3 * np.pi * r**3, rtol=0.01
    )
    d = centreline_distance(V, MODEL)
    scale = 1 / ((1 + np.cos(np.pi / N_AROUND)) / 2)  # n-gon ring sized to the mean silhouette
    np.testing.assert_allclose(d, r * scale, rtol=1e-4)
    # Rounded ends: the mesh reaches one wire radius beyond both end points along the arc.
    tip_cap = V @ MODEL.tangent_at(MODEL.tip_angle)
    assert tip_cap.max() - MODEL.tip @ MODEL.tangent_at(MODEL.tip_angle) > 0.99 * r
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0)


def test_obj_written_once_per_geometry(tmp_path):
    path = write_needle_obj(MODEL, tmp_path)
    assert path.exists() and path.suffix == ".obj"
    text = path.read_text()
    V, _, F = needle_mesh_arrays(MODEL)
    assert text.count("\nv ") == len(V) and text.count("\nf ") == len(F)
    mtime = path.stat().st_mtime_ns
    assert write_needle_obj(MODEL, tmp_path) == path and path.stat().st_mtime_ns == mtime
    thick = NeedleModel(wire_radius=0.0005)
    assert write_needle_obj(thick, tmp_path) != path


def test_band_covers_the_base_end_only():
    """The violet band: every vertex within BAND_LENGTH of arc from the base (its cap too);
    none near the tip, whose cap once wrapped round to the band (a 180° base/tip cue error)."""
    V, _, _ = needle_mesh_arrays(MODEL)
    band = band_vertices(MODEL, V)
    base, tip = MODEL.point_at(MODEL.base_angle), MODEL.point_at(MODEL.tip_angle)
    near_base = np.linalg.norm(V - base, axis=1) < 1.5 * MODEL.wire_radius
    near_tip = np.linalg.norm(V - tip, axis=1) < 0.5 * BAND_LENGTH
    assert band[near_base].all()
    assert not band[near_tip].any()
    arc = MODEL.radius * (MODEL.base_angle - MODEL.tip_angle)
    share = band.mean()
    assert 0.5 * BAND_LENGTH / arc < share < 2.0 * BAND_LENGTH / arc
