"""The bookkeeping of the needle passing through the suturing phantom, in pybullet.

:class:`PhantomBody` builds the phantom's bodies with :mod:`suture_bt.sim.phantom_build` (the
tissue block with its ridge and port squares, and the cavity floor; geometry described there)
and records what the needle does in it, in the phantom frame so a moved or rotated phantom
works. Links of the phantom body ``id``: the base link (−1) is the flat block, ``slab_links``
the ridge, ``mark_links[port name]`` the port squares; ``floor_id`` is the floor (not tissue).

Bookkeeping (:meth:`PhantomBody.update`, once per physics step): for every port, each needle
tip crossing of the port plane within ``CAPTURE_RADIUS`` of the port, with the SRC sign
convention (tip z in the port frame: + to − at an entry, − to + at an exit), the lateral
distance √(x² + y²) at the crossing (interpolated between steps), how far the tip gets out past
an exit, and the tissue strain at every engaged port.

Tissue entries (:meth:`PhantomBody.track_tip`, cheap, called by the world whenever the needle
moved, anywhere on the phantom): every outside → inside transition of the needle tip, with the
entry point (bisected on the tip's last step), the nearest port and its distance, and how deep
the tip went before it came out. A tip that is inside at the first sample (a needle that starts
or is teleported into the tissue) records no entry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p

from suture_bt.geometry.needle import NeedleModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z, PhantomModel, Port
from suture_bt.sim.phantom_build import (
    BLOCK_THICKNESS,
    BLOCK_X,
    BLOCK_Y,
    FLOOR_DEPTH,
    FLOOR_HALF_THICKNESS,
    RidgeSegment,
    build_ridge_segments,
    create_floor,
    create_phantom_body,
)
from suture_bt.sim.rendering import load_renderer
from suture_bt.transforms import invert

#: A tip crossing of a port plane is recorded when it lies within this distance of the port.
CAPTURE_RADIUS = 0.010
#: A port is engaged while the needle centre-line pierces its plane within this distance.
ENGAGE_RADIUS = 0.005
_N_CENTERLINE = 121
#: Bisection steps for an entry point on the tip's last step (≤ 20 mm / 2^20: ≤ 20 nm).
ENTRY_BISECTIONS = 20
#: A tip jump longer than this between two samples is a teleport (``set_pose``), not a motion
#: (it is 5 m/s at the world's 250 Hz bookkeeping): no entry is recorded across it.
TELEPORT_JUMP = 0.02


@dataclass
class Crossing:
    """One tip crossing of a port plane (SRC convention: +→− at entries, −→+ at exits)."""

    port: str
    pair: int
    kind: str  # "entry" or "exit"
    t: float  # interpolated time of the crossing (s)
    inward: bool  # True for + to − (tip going into the tissue)
    lateral: float  # √(x² + y²) in the port frame at the crossing (m)
    point: np.ndarray  # crossing point in the port frame
    tip_out: float = 0.0  # exits: greatest tip distance from the crossing point while out (m)

    @property
    def src_direction(self) -> bool:
        """True when the direction is the one SRC scores (into an entry, out of an exit)."""
        return self.inward if self.kind == "entry" else not self.inward


@dataclass
class Strain:
    """Distances (m) from an engaged port to the needle's circle (3-D) and plane."""

    circle: float
    plane: float


@dataclass
class TissueEntry:
    """One place where the needle tip went into the tissue (ground truth, anywhere)."""

    t: float  # interpolated time of the entry (s)
    point: np.ndarray  # entry point on the surface (world)
    nearest_port: str  # the port nearest to the entry point
    distance: float  # distance from the entry point to that port's position (m)
    # Greatest straight-line distance of the tip from the entry point while it stayed inside
    # (m): the depth reached, measured from the entry point (best effort, not along the normal).
    depth_max: float = 0.0


def _check_pose(T) -> np.ndarray:
    """A 4×4 finite pose as float array, else a ValueError with the reason."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"needle pose must be a finite 4×4 transform, got shape {T.shape}")
    return T


class PhantomBody:
    """The phantom in one pybullet client; records the needle's port crossings and strain."""

    def __init__(
        self, client: int, phantom: PhantomModel, needle_model: NeedleModel | None = None
    ) -> None:
        self.client = client
        self.phantom = phantom
        self.needle_model = needle_model if needle_model is not None else NeedleModel()
        load_renderer(client)  # bodies created before the EGL plugin loads are never drawn
        self._segments: list[RidgeSegment] = build_ridge_segments(phantom)
        self.id, self.slab_links, self.mark_links = create_phantom_body(
            client, phantom, self._segments
        )
        self.floor_id = create_floor(client, phantom)
        self.crossings: list[Crossing] = []
        self.strain: dict[str, Strain] = {}
        self.max_strain: dict[str, Strain] = {}
        self._ports = self.phantom.ports()  # world frames, fixed for this body
        self._R_port_world = np.stack([q.T[:3, :3].T for q in self._ports])  # P×3×3
        self._port_pos = np.stack([q.position for q in self._ports])  # P×3
        self._M_ports = self._R_port_world.reshape(-1, 3)  # 3P×3: world → port rotations
        self._m_ports = np.einsum("pij,pj->pi", self._R_port_world, self._port_pos).ravel()
        self._centerline = self.needle_model.centerline(_N_CENTERLINE)
        self._last_tip: np.ndarray | None = None  # tip in every port frame, P×3
        self._last_t: float | None = None
        self._open_exit: dict[int, Crossing] = {}
        self.tissue_entries: list[TissueEntry] = []
        self._T_phantom_world = invert(self.phantom.T_world_phantom)
        self._fast = self._fast_geometry()
        self._tip_prev: tuple[float, float, float] | None = None
        self._tip_prev_t = 0.0
        self._tip_inside = False
        self._open_entry: TissueEntry | None = None
        self._entry_xyz: tuple[float, ...] = (0.0, 0.0, 0.0)

    # --- the tissue solid -------------------------------------------------------------------
    def inside_tissue(self, points_world: np.ndarray) -> np.ndarray:
        """Which world points lie inside the tissue (block or ridge solid), boolean per point."""
        Ti = self._T_phantom_world
        q = np.atleast_2d(points_world) @ Ti[:3, :3].T + Ti[:3, 3]
        x, y, z = q.T
        inside = (
            (BLOCK_X[0] <= x)
            & (x <= BLOCK_X[1])
            & (BLOCK_Y[0] <= y)
            & (y <= BLOCK_Y[1])
            & (z <= TISSUE_TOP_Z)
            & (z >= TISSUE_TOP_Z - BLOCK_THICKNESS)
        )
        for seg in self._segments:
            below_flanks = np.ones(len(q), bool)
            for port in (seg.entry, seg.exit):
                below_flanks &= (q - port.T[:3, 3]) @ port.T[:3, 2] <= 0.0
            inside |= below_flanks & (seg.y0 <= y) & (y <= seg.y1) & (z >= TISSUE_TOP_Z)
        return inside

    def _fast_geometry(self) -> tuple:
        """Plain floats of the tissue solid for :meth:`_point_inside` (no numpy per call)."""
        Ti = self._T_phantom_world
        rows = tuple(tuple(float(v) for v in Ti[k, :4]) for k in range(3))
        segs = []
        for seg in self._segments:
            planes = []
            for port in (seg.entry, seg.exit):
                n, p0 = port.T[:3, 2], port.T[:3, 3]
                planes.append((float(n[0]), float(n[1]), float(n[2]), float(n @ p0)))
            segs.append((float(seg.y0), float(seg.y1), planes[0], planes[1]))
        return rows, tuple(segs)

    def _point_inside(self, x: float, y: float, z: float) -> bool:
        """:meth:`inside_tissue` for one world point in plain Python (~µs, for the tracker)."""
        (a0, a1, a2, a3), (b0, b1, b2, b3), (c0, c1, c2, c3) = self._fast[0]
        px = a0 * x + a1 * y + a2 * z + a3
        py = b0 * x + b1 * y + b2 * z + b3
        pz = c0 * x + c1 * y + c2 * z + c3
        if pz < TISSUE_TOP_Z - BLOCK_THICKNESS:
            return False
        if pz <= TISSUE_TOP_Z and BLOCK_X[0] <= px <= BLOCK_X[1] and BLOCK_Y[0] <= py <= BLOCK_Y[1]:
            return True
        if pz < TISSUE_TOP_Z:
            return False
        for y0, y1, (n0, n1, n2, d), (m0, m1, m2, e) in self._fast[1]:
            if (
                y0 <= py <= y1
                and n0 * px + n1 * py + n2 * pz <= d
                and m0 * px + m1 * py + m2 * pz <= e
            ):
                return True
        return False

    def below_floor(self, points_world: np.ndarray) -> np.ndarray:
        """Which world points lie under the top face of the cavity floor (inside it or past it),
        boolean per point: nothing solid can be there, and the floor hides it from the camera."""
        q = np.atleast_2d(points_world) @ invert(self.phantom.T_world_phantom)[:3, :3].T
        q = q + invert(self.phantom.T_world_phantom)[:3, 3]
        return q[:, 2] < TISSUE_TOP_Z - FLOOR_DEPTH + FLOOR_HALF_THICKNESS

    # --- needle bookkeeping -----------------------------------------------------------------
    def _centerline_world(self, T_world_needle: np.ndarray) -> np.ndarray:
        return self._centerline @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]

    def _in_port_frames(self, points_world: np.ndarray) -> np.ndarray:
        """World points (N×3) in every port frame: P×N×3 (one matrix product for speed)."""
        P = len(self._ports)
        flat = points_world @ self._M_ports.T - self._m_ports  # N×3P
        return flat.reshape(len(points_world), P, 3).transpose(1, 0, 2)

    def inserted(self, T_world_needle: np.ndarray) -> bool:
        """True when the needle is stuck in the tissue (its centre-line passes into it)."""
        T_world_needle = _check_pose(T_world_needle)
        return bool(self.inside_tissue(self._centerline_world(T_world_needle)).any())

    def engaged_ports(self, T_world_needle: np.ndarray) -> list[str]:
        """Ports whose plane the centre-line pierces within ``ENGAGE_RADIUS`` of the port."""
        T_world_needle = _check_pose(T_world_needle)
        local = self._in_port_frames(self._centerline_world(T_world_needle))  # P×N×3
        z = local[:, :, 2]
        pi, ni = np.nonzero(z[:, :-1] * z[:, 1:] < 0)
        if len(pi) == 0:
            return []
        a, b = local[pi, ni], local[pi, ni + 1]
        s = (a[:, 2] / (a[:, 2] - b[:, 2]))[:, None]
        c = a + s * (b - a)
        hit = np.unique(pi[np.hypot(c[:, 0], c[:, 1]) <= ENGAGE_RADIUS])
        return [self._ports[i].name for i in hit]

    def port_strain(self, T_world_needle: np.ndarray, port: Port) -> Strain:
        """Distance from a port to the needle's circle (3-D) and to its plane."""
        q = invert(T_world_needle) @ np.r_[port.position, 1.0]
        rho = np.hypot(q[0], q[1])
        return Strain(
            circle=float(np.hypot(rho - self.needle_model.radius, q[2])), plane=float(abs(q[2]))
        )

    def update(self, T_world_needle: np.ndarray, t: float) -> list[Crossing]:
        """Record tip crossings since the last call and the current strain; returns new ones."""
        T_world_needle = _check_pose(T_world_needle)
        tip = T_world_needle[:3, :3] @ self.needle_model.tip + T_world_needle[:3, 3]
        local = self._in_port_frames(tip[None])[:, 0, :]  # P×3
        prev, self._last_tip = self._last_tip, local
        new = []
        if prev is not None and self._last_t is not None:
            inward = (prev[:, 2] > 0.0) & (local[:, 2] <= 0.0)
            outward = (prev[:, 2] <= 0.0) & (local[:, 2] > 0.0)
            for i in np.nonzero(inward | outward)[0]:
                s = prev[i, 2] / (prev[i, 2] - local[i, 2])
                c = prev[i] + s * (local[i] - prev[i])
                lateral = float(np.hypot(c[0], c[1]))
                if lateral > CAPTURE_RADIUS:
                    continue
                port = self._ports[i]
                rec = Crossing(
                    port.name,
                    port.pair,
                    port.kind,
                    float(self._last_t + s * (t - self._last_t)),
                    bool(inward[i]),
                    lateral,
                    c,
                )
                self.crossings.append(rec)
                new.append(rec)
                self._open_exit.pop(int(i), None)
                if port.kind == "exit" and outward[i]:
                    self._open_exit[int(i)] = rec
        for i, rec in list(self._open_exit.items()):
            if local[i, 2] > 0.0:
                rec.tip_out = max(rec.tip_out, float(np.linalg.norm(local[i] - rec.point)))
            else:
                del self._open_exit[i]
        self._last_t = float(t)
        self.strain = {}
        for name in self.engaged_ports(T_world_needle):
            st = self.port_strain(T_world_needle, self.phantom.port(name))
            self.strain[name] = st
            m = self.max_strain.get(name)
            if m is None or st.circle > m.circle:
                self.max_strain[name] = st
        return new

    def track_tip(self, tip_world, t: float) -> TissueEntry | None:
        """Follow the needle tip (world; None: it did not move) and record each tissue entry.

        Cheap (plain Python) so the world can call it whenever the needle moved, far from the
        ports too. The first sample after construction or :meth:`reset_entry_tracking` only
        sets the state: a tip already inside then records no entry. Returns a new entry.
        """
        if tip_world is None:
            self._tip_prev_t = float(t)
            return None
        x, y, z = (float(v) for v in tip_world)
        inside = self._point_inside(x, y, z)
        prev, prev_inside, t0 = self._tip_prev, self._tip_inside, self._tip_prev_t
        self._tip_prev, self._tip_inside, self._tip_prev_t = (x, y, z), inside, float(t)
        if not inside:
            self._open_entry = None
            return None
        if prev is None:
            return None
        if prev_inside:
            e = self._open_entry
            if e is not None:
                e.depth_max = max(e.depth_max, math.dist((x, y, z), self._entry_xyz))
            return None
        a, b = np.array(prev), np.array((x, y, z))
        if np.linalg.norm(b - a) > TELEPORT_JUMP:
            return None  # a teleport into the tissue, not a motion: nothing to record
        lo, hi = 0.0, 1.0  # a(lo) outside, a(hi) inside
        for _ in range(ENTRY_BISECTIONS):
            mid = (lo + hi) / 2
            if self._point_inside(*(a + mid * (b - a))):
                hi = mid
            else:
                lo = mid
        point = a + hi * (b - a)
        d_ports = np.linalg.norm(self._port_pos - point, axis=1)
        k = int(np.argmin(d_ports))
        entry = TissueEntry(
            t0 + hi * (float(t) - t0),
            point,
            self._ports[k].name,
            float(d_ports[k]),
            float(np.linalg.norm(b - point)),
        )
        self.tissue_entries.append(entry)
        self._open_entry, self._entry_xyz = entry, tuple(float(v) for v in point)
        return entry

    def reset_entry_tracking(self) -> None:
        """Forget the tip's last place (after a teleport): the next sample records no entry."""
        self._tip_prev = None
        self._open_entry = None

    def reset_tracking(self) -> None:
        """Forget the last tip position (call after teleporting the needle)."""
        self._last_tip = None
        self._last_t = None
        self._open_exit.clear()

    def remove(self) -> None:
        """Take the phantom's bodies (tissue with its ridge and port squares, and the floor) out
        of the client, e.g. before building it again at another pose."""
        for body in (self.id, self.floor_id):
            p.removeBody(body, physicsClientId=self.client)
