"""Height of the phantom's tissue surface under a point: the flat top and the ridge of the ports.

Known task geometry (the phantom's model, placed by the scene's phantom pose), no simulator: a
flat tissue top at ``TISSUE_TOP_Z`` and, for each port pair, a ridge segment bounded by the two
flank planes through its entry and exit ports (their outward normals), reaching halfway to the
neighbouring pairs and ``RIDGE_END_MARGIN`` past the outer ones. Skills use it to keep a held
needle clear of the tissue wherever the phantom stands; the flat top is taken as unbounded (a
point beside the block is judged as if over it: the safe side).
"""

from __future__ import annotations

import numpy as np

from suture_bt.geometry.phantom import TISSUE_TOP_Z, TISSUE_X, TISSUE_Y, PhantomModel

#: How far the ridge runs past the outer pairs (m, along the phantom's y).
RIDGE_END_MARGIN = 0.012


def ridge_segments(phantom: PhantomModel) -> list[tuple[float, float, np.ndarray, np.ndarray]]:
    """Per pair, sorted by y: (y0, y1, entry frame, exit frame) in the phantom frame."""
    pairs = []
    for i in range(1, phantom.num_pairs + 1):
        entry = next(p for p in phantom.ports_in_phantom if p.name == f"entry{i}")
        exit_ = next(p for p in phantom.ports_in_phantom if p.name == f"exit{i}")
        pairs.append((entry.T, exit_.T))
    pairs.sort(key=lambda pe: pe[0][1, 3])
    ys = [0.5 * (e[1, 3] + x[1, 3]) for e, x in pairs]
    edges = (
        [ys[0] - RIDGE_END_MARGIN]
        + [(a + b) / 2 for a, b in zip(ys[:-1], ys[1:], strict=True)]
        + [ys[-1] + RIDGE_END_MARGIN]
    )
    return [(y0, y1, e, x) for (e, x), y0, y1 in zip(pairs, edges[:-1], edges[1:], strict=True)]


def _plane_height(T_port: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Height (phantom z) of a port's flank plane above the points ``xy`` (N×2)."""
    n, p = T_port[:3, 2], T_port[:3, 3]
    return p[2] - ((xy[:, 0] - p[0]) * n[0] + (xy[:, 1] - p[1]) * n[1]) / n[2]


def surface_height(phantom: PhantomModel, points_world: np.ndarray) -> np.ndarray:
    """Tissue surface height (phantom-frame z, m) under each world point."""
    Ti = np.linalg.inv(phantom.T_world_phantom)
    q = np.atleast_2d(points_world) @ Ti[:3, :3].T + Ti[:3, 3]
    xy = q[:, :2]
    height = np.full(len(q), TISSUE_TOP_Z)
    for y0, y1, entry, exit_ in ridge_segments(phantom):
        ridge = np.minimum(_plane_height(entry, xy), _plane_height(exit_, xy))
        on = (y0 <= xy[:, 1]) & (xy[:, 1] <= y1)
        height = np.where(on, np.maximum(height, ridge), height)
    return height


def height_above_tissue(phantom: PhantomModel, points_world: np.ndarray) -> np.ndarray:
    """Height (m) of each world point above the tissue surface under it, along the phantom's
    up axis (negative: inside the tissue)."""
    Ti = np.linalg.inv(phantom.T_world_phantom)
    z = (np.atleast_2d(points_world) @ Ti[:3, :3].T + Ti[:3, 3])[:, 2]
    return z - surface_height(phantom, points_world)


def solid_pieces(phantom: PhantomModel) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """The tissue solid as convex pieces, each a list of (world point, world outward normal)
    planes it lies below: the block under its flat top within ``TISSUE_X`` × ``TISSUE_Y``, and
    per pair its ridge segment (under both flanks, between the segment's y ends)."""
    T = np.asarray(phantom.T_world_phantom, float)
    R, t = T[:3, :3], T[:3, 3]

    def plane(point, normal) -> tuple[np.ndarray, np.ndarray]:
        return R @ np.asarray(point, float) + t, R @ np.asarray(normal, float)

    (x0, x1), (y0, y1) = TISSUE_X, TISSUE_Y
    block = [
        plane((0.0, 0.0, TISSUE_TOP_Z), (0.0, 0.0, 1.0)),
        plane((x0, 0.0, 0.0), (-1.0, 0.0, 0.0)),
        plane((x1, 0.0, 0.0), (1.0, 0.0, 0.0)),
        plane((0.0, y0, 0.0), (0.0, -1.0, 0.0)),
        plane((0.0, y1, 0.0), (0.0, 1.0, 0.0)),
    ]
    pieces = [block]
    for s0, s1, entry, exit_ in ridge_segments(phantom):
        pieces.append(
            [
                plane(entry[:3, 3], entry[:3, 2]),
                plane(exit_[:3, 3], exit_[:3, 2]),
                plane((0.0, s0, 0.0), (0.0, -1.0, 0.0)),
                plane((0.0, s1, 0.0), (0.0, 1.0, 0.0)),
            ]
        )
    return pieces
