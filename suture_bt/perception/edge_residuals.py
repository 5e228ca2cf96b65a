"""The fit's edge objective: mask edge rays against the wire (the arc's tube), in pixels.

Every mask edge point back-projects to a ray that should be tangent to the wire: its distance
to the centre-line arc should be the wire radius (rays past either end measure to the end
point, the hemispherical cap). Residuals in pixels at the point's depth, and their analytic
Jacobian in the pose. The fit's inner loop runs the same arithmetic compiled
(:mod:`edge_kernel`); these numpy functions serve single evaluations and are its reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.needle_projection import pixel_rays
from suture_bt.perception.tissue_cut import TissueCut, clamp_all
from suture_bt.transforms import invert

#: Samples of the arc angle for the nearest-point search before Newton polishing.
N_THETA_GRID = 24


@dataclass
class EdgeRays:
    """Edge rays of both eyes in the left camera frame, with their pixel scale data."""

    origins: np.ndarray  # (N, 3)
    dirs: np.ndarray  # (N, 3) unit
    dz: np.ndarray  # (N,) z of the direction in its own eye frame
    focal: np.ndarray  # (N,) focal length of its eye (px)
    eye: np.ndarray  # (N,) 0 left, 1 right
    #: Where the tissue hides the arc (a needle in a port): rays measure to the seen arc.
    cut: TissueCut | None = None

    def subset(self, idx: np.ndarray) -> EdgeRays:
        return EdgeRays(
            self.origins[idx],
            self.dirs[idx],
            self.dz[idx],
            self.focal[idx],
            self.eye[idx],
            self.cut,
        )

    def spans(self, T: np.ndarray) -> np.ndarray:
        """Hidden spans (K, 2, 2) of the arc at poses T (all NaN without a cut)."""
        if self.cut is None:
            return np.full((len(T), 2, 2), np.nan)
        return self.cut.spans(T)

    def __len__(self) -> int:
        return len(self.dz)


def edge_rays(stereo: StereoCameraModel, left_uv: np.ndarray, right_uv: np.ndarray) -> EdgeRays:
    """Rays through left/right edge pixels, expressed in the left camera frame."""
    T_left_right = invert(stereo.left.T_world_cam) @ stereo.right.T_world_cam
    dl = pixel_rays(stereo.left, left_uv) if len(left_uv) else np.zeros((0, 3))
    dr = pixel_rays(stereo.right, right_uv) if len(right_uv) else np.zeros((0, 3))
    dirs = np.concatenate([dl, dr @ T_left_right[:3, :3].T], 0)
    origins = np.concatenate(
        [np.zeros((len(dl), 3)), np.broadcast_to(T_left_right[:3, 3], (len(dr), 3))], 0
    )
    dz = np.concatenate([dl[:, 2], dr[:, 2]])
    focal = np.concatenate([np.full(len(dl), stereo.left.fx), np.full(len(dr), stereo.right.fx)])
    eye = np.concatenate([np.zeros(len(dl), int), np.ones(len(dr), int)])
    return EdgeRays(origins, dirs, dz, focal, eye)


def _to_needle(T: np.ndarray, rays: EdgeRays) -> tuple[np.ndarray, np.ndarray]:
    """Ray origins and directions in each pose's needle frame, component first: (3, K, N) each
    (contiguous components keep the arc maths below fast)."""
    R, p = T[:, :3, :3], T[:, :3, 3]
    o = np.matmul(rays.origins[None] - p[:, None], R)
    d = np.matmul(rays.dirs[None], R)
    return np.ascontiguousarray(o.transpose(2, 0, 1)), np.ascontiguousarray(d.transpose(2, 0, 1))


def _arc_f(theta, o, d, r):
    """Squared distance f from the arc point at theta to each ray's line, and its along-ray t.

    ``o``, ``d``: component-first ray origins and directions in the needle frame (see
    :func:`_to_needle`).
    """
    c, s = np.cos(theta), np.sin(theta)
    a, b = r * c - o[0], r * s - o[1]
    qd = a * d[0] + b * d[1] - o[2] * d[2]
    return a * a + b * b + o[2] * o[2] - qd * qd, qd


def _newton_step(theta, o, d, od, r):
    """Newton step f'/f'' of the squared ray distance f in theta, 0 where f is not convex.

    With u = cos θ d0 + sin θ d1, v = cos θ d1 - sin θ d0 and the along-ray distance
    qd = r u - o·d: f'/2r = o0 sin θ - o1 cos θ - qd v, f''/2r = o0 cos θ + o1 sin θ - r v² + qd u.
    """
    c, s = np.cos(theta), np.sin(theta)
    u = c * d[0] + s * d[1]
    v = c * d[1] - s * d[0]
    qd = r * u - od
    num = o[0] * s - o[1] * c - qd * v
    den = o[0] * c + o[1] * s - r * v * v + qd * u
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def nearest_arc_angle(
    o: np.ndarray,
    d: np.ndarray,
    model: NeedleModel,
    grid: int = N_THETA_GRID,
    start: np.ndarray | None = None,
):
    """Arc angle (K, N) of the centre-line point nearest each ray (clamped to the arc's ends).

    A grid search then Newton steps; with ``start`` (angles of a nearby pose) Newton only.
    ``o``, ``d`` are component first (see :func:`_to_needle`).
    """
    lo, hi = model.tip_angle, model.base_angle
    r = model.radius
    od = o[0] * d[0] + o[1] * d[1] + o[2] * d[2]
    if start is None:
        # f(θ) = r² + |o|² - 2r (o0 cos θ + o1 sin θ) - (r (d0 cos θ + d1 sin θ) - o·d)²: the
        # θ-dependent part for every grid angle at once by two small matrix products.
        g = np.linspace(lo, hi, grid)
        cs = np.stack([np.cos(g), np.sin(g)])
        m = np.stack([o[0], o[1]], -1) @ cs
        q = np.stack([d[0], d[1]], -1) @ cs
        q *= r
        q -= od[..., None]
        q *= q
        m *= -2 * r
        m -= q
        theta = g[np.argmin(m, -1)]
    else:
        theta = start
    for _ in range(2):
        step = _newton_step(theta, o, d, od, r)
        step = np.clip(step, -(hi - lo) / grid, (hi - lo) / grid)
        theta = np.clip(theta - step, lo, hi)
    return theta


def residuals(
    T: np.ndarray,
    rays: EdgeRays,
    model: NeedleModel,
    theta: np.ndarray | None = None,
    theta_start: np.ndarray | None = None,
    grid: int = N_THETA_GRID,
):
    """Edge residuals (K, N) in pixels for poses T (K, 4, 4); also the arc angles used.

    ``theta`` fixes the nearest-point angles; ``theta_start`` seeds their Newton search from a
    nearby pose's angles.
    """
    o, d = _to_needle(T, rays)
    if theta is None:
        theta = nearest_arc_angle(o, d, model, grid=grid, start=theta_start)
        if rays.cut is not None:
            theta = _to_seen(theta, rays.spans(T), model)
    f, qd = _arc_f(theta, o, d, model.radius)
    dist = np.sqrt(np.maximum(f, 0.0))
    depth = qd * rays.dz[None]
    r = (dist - model.wire_radius) * rays.focal[None] / np.where(depth > 1e-6, depth, np.nan)
    return r, theta


def _to_seen(theta: np.ndarray, spans: np.ndarray, model: NeedleModel):
    """Angles (K, N) moved out of the hidden spans (K, 2, 2) to their seen ends."""
    return clamp_all(
        np.ascontiguousarray(theta, dtype=float),
        np.ascontiguousarray(spans, dtype=float),
        float(model.tip_angle),
        float(model.base_angle),
    )


def edge_jacobian(
    T: np.ndarray,
    dT: np.ndarray,
    rays: EdgeRays,
    model: NeedleModel,
    theta: np.ndarray,
) -> np.ndarray:
    """Jacobian (K, P, N) of the edge residuals at poses T (K, 4, 4), given the poses'
    derivatives dT (K, P, 4, 4) in P parameters.

    The nearest-point angles stay fixed: the distance is stationary in them (exactly so at
    interior points; clamped end points do not move). For a ray with unit direction d through
    the arc point X, offset a = X - origin, along-ray distance qd = a·d, perpendicular
    e = a - qd d and residual r = (|e| - wire radius) f / (qd d_z):
    dr/dX = f / (qd d_z) (e / |e| - (|e| - wire radius) / qd · d). With X = R P(θ) + p, in the
    needle frame R^T dX = (R^T dR) P + R^T dp: one small batched matrix product per start.
    """
    o, d = _to_needle(T, rays)
    c, s = np.cos(theta), np.sin(theta)
    P = [model.radius * c, model.radius * s]
    a0, a1 = P[0] - o[0], P[1] - o[1]
    qd = a0 * d[0] + a1 * d[1] - o[2] * d[2]
    a = (a0, a1, -o[2])
    e = [a[i] - qd * d[i] for i in range(3)]
    dist = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    k = rays.focal[None] / (qd * rays.dz[None])
    inv = 1.0 / np.maximum(dist, 1e-12)
    along = (dist - model.wire_radius) / qd
    g = [k * (e[i] * inv - along * d[i]) for i in range(3)]
    H = np.stack([g[i] * P[n] for i in range(3) for n in range(2)] + g, 1)  # (K, 9, N)
    R = T[:, :3, :3]
    A = np.einsum("kmi,kjmn->kjin", R, dT[..., :3, :2]).reshape(*dT.shape[:2], 6)
    b = np.einsum("kmi,kjm->kji", R, dT[..., :3, 3])
    J = np.concatenate([A, b], -1) @ H
    if rays.cut is not None:
        # A ray measured to the cut: the cut's end moves along the arc with the pose.
        spans = rays.spans(T).reshape(len(T), 4)
        at = np.stack([np.isclose(theta, spans[:, j, None], rtol=0, atol=1e-12) for j in range(4)])
        if at.any():
            h = 1e-7
            Tp = (T[:, None] + h * dT).reshape(-1, 4, 4)
            moved = (rays.spans(Tp).reshape(*dT.shape[:2], 4) - spans[:, None]) / h
            moved = np.where(np.isfinite(moved), moved, 0.0)  # (K, P, 4)
            dth = np.einsum("jkn,kpj->kpn", at.astype(float), moved)  # (K, P, N)
            J += dth * (g[1] * P[0] - g[0] * P[1])[:, None]
    return J
