"""The needle as an OBJ tube of its true wire radius, with hemispherical end caps.

The base end carries a violet band (the swage, where the suture thread is attached on a real
needle) so that images can tell base from tip: the mesh's texture coordinates put the band's
vertices on the violet half of a two-colour texture, written next to the mesh.

pybullet's capsule/cylinder visuals render about 1 mm too fat and EGL silently skips in-memory
meshes (DESIGN.md §5), so the needle is drawn from a mesh file. Files are written once per
geometry into a cache folder, named by a hash of their content parameters.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

from suture_bt.geometry.needle import NeedleModel

#: Default resolution: segments along the arc, vertices around the wire, rings per end cap.
N_ALONG = 120
N_AROUND = 16
N_CAP = 4
#: Length of the violet swage band at the base end, along the arc (m).
BAND_LENGTH = 0.003
#: Texture colours (8-bit RGB): the needle's metal is white-lit grey, the band violet.
METAL_RGB = (158, 161, 168)
BAND_RGB = (150, 60, 170)


def needle_mesh_arrays(
    model: NeedleModel, n_along: int = N_ALONG, n_around: int = N_AROUND, n_cap: int = N_CAP
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices N×3, normals N×3, triangles M×3 with 0-based indices), needle frame."""
    if n_along < 1 or n_around < 3 or n_cap < 1:
        raise ValueError("mesh resolution too low (need n_along ≥ 1, n_around ≥ 3, n_cap ≥ 1)")
    # A regular n-gon ring has a silhouette half-width between wr·cos(π/n) and wr; scale it so
    # the mean matches the true wire radius.
    wr = model.wire_radius / ((1.0 + np.cos(np.pi / n_around)) / 2.0)
    phi = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    ez = np.array([0.0, 0.0, 1.0])

    def frame(a: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        centre = model.point_at(a)
        radial = np.array([np.cos(a), np.sin(a), 0.0])
        return centre, radial, model.tangent_at(a)

    def ring(centre, radial, axis_offset, ring_radius):
        dirs = np.cos(phi)[:, None] * radial + np.sin(phi)[:, None] * ez
        return centre + axis_offset + ring_radius * dirs, dirs

    verts: list[np.ndarray] = []
    norms: list[np.ndarray] = []
    # Base cap (pole first, outward = −tangent at the base), then the tube, then the tip cap.
    c, rad, t = frame(model.base_angle)
    verts.append((c - wr * t)[None])
    norms.append((-t)[None])
    betas = np.linspace(0.0, np.pi / 2, n_cap + 1)[1:]  # from the pole towards the equator
    for b in betas[:-1]:
        v, d = ring(c, rad, -wr * np.cos(b) * t, wr * np.sin(b))
        verts.append(v)
        norms.append(np.sin(b) * d - np.cos(b) * t)
    for a in np.linspace(model.base_angle, model.tip_angle, n_along + 1):
        c, rad, t = frame(a)
        v, d = ring(c, rad, 0.0, wr)
        verts.append(v)
        norms.append(d)
    for b in betas[::-1][1:]:
        v, d = ring(c, rad, wr * np.cos(b) * t, wr * np.sin(b))
        verts.append(v)
        norms.append(np.sin(b) * d + np.cos(b) * t)
    verts.append((c + wr * t)[None])
    norms.append(t[None])
    V = np.concatenate(verts)
    N = np.concatenate(norms)
    N /= np.linalg.norm(N, axis=1, keepdims=True)

    n_rings = (len(V) - 2) // n_around
    tris = []
    first_ring = 1
    j = np.arange(n_around)
    jn = (j + 1) % n_around
    # Orientation: rings run base → tip (along t); dirs go radial → ez, so (t, d_j, d_j+1) is
    # right-handed: a quad (i,j),(i+1,j),(i+1,j+1),(i,j+1) wound this way faces outward.
    for i in range(n_rings - 1):
        a0 = first_ring + i * n_around
        a1 = a0 + n_around
        tris.append(np.stack([a0 + j, a0 + jn, a1 + jn], 1))
        tris.append(np.stack([a0 + j, a1 + jn, a1 + j], 1))
    last = first_ring + (n_rings - 1) * n_around
    tris.append(np.stack([np.zeros(n_around, int), first_ring + jn, first_ring + j], 1))
    tris.append(np.stack([np.full(n_around, len(V) - 1), last + j, last + jn], 1))
    F = np.concatenate(tris)
    F = _orient_outward(V, N, F)
    return V, N, F


def _orient_outward(V: np.ndarray, N: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Flip any triangle whose geometric normal disagrees with its vertex normals."""
    n_geo = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.einsum("ij,ij->i", n_geo, N[F].sum(1)) < 0
    F = F.copy()
    F[flip] = F[flip][:, [0, 2, 1]]
    return F


def mesh_cache_dir() -> Path:
    """Folder for generated meshes (``SUTURE_BT_MESH_DIR`` or a folder in the temp dir)."""
    d = Path(os.environ.get("SUTURE_BT_MESH_DIR", Path(tempfile.gettempdir()) / "suture_bt_mesh"))
    d.mkdir(parents=True, exist_ok=True)
    return d


def band_vertices(model: NeedleModel, V: np.ndarray) -> np.ndarray:
    """Boolean per vertex: within ``BAND_LENGTH`` of arc from the base end (base cap included).

    Angles are measured from the arc's bisector, so the tip cap (just past the tip angle) is far
    from the base and stays metal.
    """
    mid = 0.5 * (model.base_angle + model.tip_angle)
    angle = mid + np.angle(np.exp(1j * (np.arctan2(V[:, 1], V[:, 0]) - mid)))
    return (model.base_angle - angle) * model.radius < BAND_LENGTH


def write_needle_texture(folder: Path | None = None) -> Path:
    """Write (once) the 16×16 two-colour texture: u < 0.5 band violet, u ≥ 0.5 metal grey."""
    import cv2

    name = "needle_texture_" + "_".join(map(str, BAND_RGB + METAL_RGB)) + ".png"
    path = (folder if folder is not None else mesh_cache_dir()) / name
    if path.exists():
        return path
    tex = np.zeros((16, 16, 3), np.uint8)
    tex[:, :8] = BAND_RGB[::-1]  # OpenCV writes BGR
    tex[:, 8:] = METAL_RGB[::-1]
    tmp = path.with_suffix(f".{os.getpid()}.tmp.png")
    cv2.imwrite(str(tmp), tex)
    os.replace(tmp, path)
    return path


def write_needle_obj(model: NeedleModel, folder: Path | None = None) -> Path:
    """Write (once) the needle mesh as OBJ in the needle frame, metres; return its path.

    Texture coordinates map the base band to the violet half of :func:`write_needle_texture`.
    """
    key = f"{model.radius:.9g}_{model.base_angle:.9g}_{model.tip_angle:.9g}_{model.wire_radius:.9g}"
    key += f"_{N_ALONG}_{N_AROUND}_{N_CAP}_{BAND_LENGTH:.6g}_v4"
    name = "needle_" + hashlib.sha1(key.encode()).hexdigest()[:16] + ".obj"
    path = (folder if folder is not None else mesh_cache_dir()) / name
    if path.exists():
        return path
    V, N, F = needle_mesh_arrays(model)
    lines = [f"# suture-bt needle {key}", "o needle"]
    lines += [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in V]
    lines += [f"vt {u:.2f} 0.5" for u in np.where(band_vertices(model, V), 0.25, 0.75)]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in N]
    lines += [
        f"f {a + 1}/{a + 1}/{a + 1} {b + 1}/{b + 1}/{b + 1} {c + 1}/{c + 1}/{c + 1}"
        for a, b, c in F
    ]
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, path)  # atomic: concurrent writers produce the same file
    return path
