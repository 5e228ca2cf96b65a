"""The suturing phantom's pybullet bodies: the tissue block with its ridge and port marks, and
the cavity floor.

Only the building lives here; the bookkeeping of the needle passing through the phantom is
:mod:`suture_bt.sim.phantom_body`, which builds the bodies with these functions and reads the
block and ridge geometry they define.

Geometry (all in the phantom frame, so a moved or rotated phantom works): a flat tissue block
whose top is at ``TISSUE_TOP_Z`` and, for each port pair, a ridge segment whose two flanks are
the planes through that pair's entry and exit ports with the ports' outward normals (pitched
∓46.1°). The flanks are thin box slabs (boxes render and collide exactly; the interior of the
ridge is never seen). Each port is marked by a dark 5 × 5 mm square (a thin box without
collision) lying on its flank. A large dark floor 3 cm below (a separate body, not tissue)
stands for the body cavity.

Links of the phantom body: the base link (−1) is the flat block, then the ridge slabs, then
one port square per port.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pybullet as p

from suture_bt.geometry.phantom import (
    PORT_MARK_SIZE,
    TISSUE_TOP_Z,
    TISSUE_X,
    TISSUE_Y,
    PhantomModel,
    Port,
)
from suture_bt.geometry.tissue_surface import RIDGE_END_MARGIN
from suture_bt.transforms import make_transform, quat_xyzw

#: Flat block: x and y extent (phantom frame, metres) and thickness below ``TISSUE_TOP_Z``.
BLOCK_X, BLOCK_Y = TISSUE_X, TISSUE_Y  # the known phantom model's
BLOCK_THICKNESS = 0.01
#: Ridge flank slabs: thickness, and how far they reach below the block top (hidden).
SLAB_THICKNESS = 0.002
SLAB_SINK = 0.002
#: Height step of the boxes that fill the ridge behind the slabs.
FILL_LAYER = 0.001
MARK_THICKNESS = 0.0002
#: A large dark floor under the tissue: the body cavity seen around the phantom (every view
#: ray of the endoscope ends on it, so images need no background fill).
FLOOR_HALF_SIZE = 0.5
FLOOR_DEPTH = 0.03
FLOOR_HALF_THICKNESS = 0.001
FLOOR_RGBA = (0.09, 0.05, 0.05, 1.0)
TISSUE_RGBA = (0.86, 0.56, 0.53, 1.0)
RIDGE_RGBA = (0.83, 0.50, 0.48, 1.0)
MARK_RGBA = (0.12, 0.09, 0.09, 1.0)


@dataclass
class RidgeSegment:
    """A ridge segment: y range and the two flank planes (point, outward normal), phantom frame."""

    y0: float
    y1: float
    entry: Port
    exit: Port
    slabs: list[np.ndarray] = field(default_factory=list)  # slab frames (phantom frame)
    half_extents: list[np.ndarray] = field(default_factory=list)


def _flank_slab(port: Port, peak_x: float, y0: float, y1: float) -> tuple[np.ndarray, np.ndarray]:
    """Frame and half extents of a slab whose top face is the port's flank, base to peak."""
    R = port.T[:3, :3]
    n, u = R[:, 2], R[:, 0]  # normal, in-plane direction perpendicular to y
    p0 = port.T[:3, 3]
    # Points on the flank at the peak x and SLAB_SINK below the block top, as in-plane offsets.
    s_peak = (peak_x - p0[0]) / u[0]
    s_base = (TISSUE_TOP_Z - SLAB_SINK - p0[2]) / u[2]
    s0, s1 = sorted((s_peak, s_base))
    centre = p0 + u * (s0 + s1) / 2 - n * SLAB_THICKNESS / 2
    centre[1] = (y0 + y1) / 2
    half = np.array([(s1 - s0) / 2, (y1 - y0) / 2, SLAB_THICKNESS / 2])
    return make_transform(R, centre), half


def _flank_x(port: Port, z: float) -> float:
    """x where a flank plane (it contains the y direction) is at height z."""
    n, p0 = port.T[:3, 2], port.T[:3, 3]
    return float(p0[0] - n[2] * (z - p0[2]) / n[0])


def _fill_layers(
    entry: Port, exit_: Port, peak_x: float, y0: float, y1: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Nested upright boxes inside the ridge, so its ends look solid (stairs hidden by slabs)."""
    peak_z = entry.T[2, 3] - entry.T[0, 2] * (peak_x - entry.T[0, 3]) / entry.T[2, 2]
    bottom = TISSUE_TOP_Z - SLAB_SINK
    out = []
    for z in np.arange(TISSUE_TOP_Z + FILL_LAYER, peak_z - SLAB_THICKNESS, FILL_LAYER):
        xe, xx = _flank_x(entry, z), _flank_x(exit_, z)
        centre = ((xe + xx) / 2, (y0 + y1) / 2, (bottom + z) / 2)
        half = np.array([(xx - xe) / 2, (y1 - y0) / 2, (z - bottom) / 2])
        out.append((make_transform(position=centre), half))
    return out


def _peak_x(entry: Port, exit_: Port) -> float:
    """x of the line where the two flank planes meet (they both contain the y direction)."""
    ne, nx = entry.T[:3, 2], exit_.T[:3, 2]
    pe, px = entry.T[:3, 3], exit_.T[:3, 3]
    # n·(q − p) = 0 for both planes in (x, z): solve the 2×2 system.
    A = np.array([[ne[0], ne[2]], [nx[0], nx[2]]])
    b = np.array([ne[0] * pe[0] + ne[2] * pe[2], nx[0] * px[0] + nx[2] * px[2]])
    return float(np.linalg.solve(A, b)[0])


def build_ridge_segments(phantom: PhantomModel) -> list[RidgeSegment]:
    """Per port pair, sorted by y: the ridge segment with its flank slabs and fill boxes."""
    pairs = [
        (
            next(q for q in phantom.ports_in_phantom if q.name == f"entry{i}"),
            next(q for q in phantom.ports_in_phantom if q.name == f"exit{i}"),
        )
        for i in range(1, phantom.num_pairs + 1)
    ]
    pairs.sort(key=lambda pe: pe[0].T[1, 3])
    ys = [pe[0].T[1, 3] for pe in pairs]
    edges = (
        [ys[0] - RIDGE_END_MARGIN]
        + [(a + b) / 2 for a, b in zip(ys[:-1], ys[1:], strict=True)]
        + [ys[-1] + RIDGE_END_MARGIN]
    )
    segments = []
    for (entry, exit_), y0, y1 in zip(pairs, edges[:-1], edges[1:], strict=True):
        seg = RidgeSegment(y0, y1, entry, exit_)
        peak = _peak_x(entry, exit_)
        for port in (entry, exit_):
            T, half = _flank_slab(port, peak, y0, y1)
            seg.slabs.append(T)
            seg.half_extents.append(half)
        for T, half in _fill_layers(entry, exit_, peak, y0, y1):
            seg.slabs.append(T)
            seg.half_extents.append(half)
        segments.append(seg)
    return segments


def create_phantom_body(
    client: int, phantom: PhantomModel, segments: list[RidgeSegment]
) -> tuple[int, list[int], dict[str, int]]:
    """The static tissue body: (body id, ridge slab links, port square link per port name)."""
    c = client
    block_half = [(BLOCK_X[1] - BLOCK_X[0]) / 2, (BLOCK_Y[1] - BLOCK_Y[0]) / 2]
    block_half.append(BLOCK_THICKNESS / 2)
    block_centre = [
        (BLOCK_X[0] + BLOCK_X[1]) / 2,
        (BLOCK_Y[0] + BLOCK_Y[1]) / 2,
        TISSUE_TOP_Z - BLOCK_THICKNESS / 2,
    ]
    base_col = p.createCollisionShape(
        p.GEOM_BOX, halfExtents=block_half, collisionFramePosition=block_centre,
        physicsClientId=c,
    )  # fmt: skip
    base_vis = p.createVisualShape(
        p.GEOM_BOX, halfExtents=block_half, visualFramePosition=block_centre,
        rgbaColor=list(TISSUE_RGBA), specularColor=[0.2, 0.2, 0.2], physicsClientId=c,
    )  # fmt: skip
    frames, cols, vis = [], [], []
    for seg in segments:
        for k, (T, half) in enumerate(zip(seg.slabs, seg.half_extents, strict=True)):
            frames.append(T)
            collides = k < 2  # the two flank slabs; the fill behind them is visual only
            cols.append(
                p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=c)
                if collides
                else -1
            )
            vis.append(
                p.createVisualShape(
                    p.GEOM_BOX,
                    halfExtents=list(half),
                    rgbaColor=list(RIDGE_RGBA),
                    specularColor=[0.2, 0.2, 0.2],
                    physicsClientId=c,
                )  # fmt: skip
            )
    n_slabs = len(frames)
    mark_half = [PORT_MARK_SIZE / 2, PORT_MARK_SIZE / 2, MARK_THICKNESS / 2]
    mark_links = {}
    for port in phantom.ports_in_phantom:
        T = port.T @ make_transform(position=(0, 0, MARK_THICKNESS / 2))
        mark_links[port.name] = len(frames)
        frames.append(T)
        cols.append(-1)
        vis.append(
            p.createVisualShape(
                p.GEOM_BOX,
                halfExtents=mark_half,
                rgbaColor=list(MARK_RGBA),
                specularColor=[0.1, 0.1, 0.1],
                physicsClientId=c,
            )  # fmt: skip
        )
    Tw = phantom.T_world_phantom
    n = len(frames)
    body = p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=base_col,
        baseVisualShapeIndex=base_vis,
        basePosition=list(Tw[:3, 3]),
        baseOrientation=list(quat_xyzw(Tw[:3, :3])),
        linkMasses=[0.0] * n,
        linkCollisionShapeIndices=cols,
        linkVisualShapeIndices=vis,
        linkPositions=[list(T[:3, 3]) for T in frames],
        linkOrientations=[list(quat_xyzw(T[:3, :3])) for T in frames],
        linkInertialFramePositions=[[0, 0, 0]] * n,
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * n,
        linkParentIndices=[0] * n,
        linkJointTypes=[p.JOINT_FIXED] * n,
        linkJointAxis=[[0, 0, 0]] * n,
        physicsClientId=c,
    )
    p.changeDynamics(body, -1, lateralFriction=1.0, physicsClientId=c)
    for link in range(n):
        p.changeDynamics(body, link, lateralFriction=1.0, physicsClientId=c)
    return body, list(range(n_slabs)), mark_links


def create_floor(client: int, phantom: PhantomModel) -> int:
    """A separate static body: large dark floor FLOOR_DEPTH below the tissue top."""
    c = client
    half = [FLOOR_HALF_SIZE, FLOOR_HALF_SIZE, FLOOR_HALF_THICKNESS]
    T = phantom.T_world_phantom @ make_transform(position=(0.0, 0.0, TISSUE_TOP_Z - FLOOR_DEPTH))
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=c)
    vis = p.createVisualShape(
        p.GEOM_BOX, halfExtents=half, rgbaColor=list(FLOOR_RGBA), specularColor=[0, 0, 0],
        physicsClientId=c,
    )  # fmt: skip
    return p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=col,
        baseVisualShapeIndex=vis,
        basePosition=list(T[:3, 3]),
        baseOrientation=list(quat_xyzw(T[:3, :3])),
        physicsClientId=c,
    )
