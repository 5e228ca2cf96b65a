"""Stereo needle-pose fit: the seed's parameterisation, an unbiased edge objective, batched LM.

Objective (one-sided, mask → model, so occluded parts of the needle cost nothing): every mask
edge point (midpoint between a needle pixel and a 4-neighbour background pixel) back-projects
to a ray that should be tangent to the wire. The wire is the union of spheres of the wire
radius along the centre-line arc, so a ray is tangent exactly when its distance to the arc is
the wire radius; the residual is that distance minus the radius, in pixels at the point's
depth. Rays past either end measure to the end point, which is the hemispherical cap. Unlike a
chamfer to the centre-line this has no pull along the line of sight (DESIGN.md §5).
Minimised by Levenberg-Marquardt with robust weights, vectorised over many starts (the
tilt-mirror ambiguity), on the parameters of :mod:`needle_projection`: Cauchy while searching
(wide basins), Geman-McClure for the final polish and choice, so a few stray mask pixels (a
sliver of jaw the colour test kept) cannot pull the answer onto a pose that half-explains them.
Optional extra terms: free space (experimental, off) and confident keypoints (search only).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.needle_projection import (
    end_pixels,
    params_to_pose,
    phi_from_base_depth,
    pixel_rays,
    pose_to_params,
)
from suture_bt.transforms import invert

#: Finite-difference steps of the six parameters (px, px, px, px, rad, rad) for the pose's
#: derivatives and the extra terms' (the edge residuals' derivatives are analytic).
FD_STEPS = np.array([0.02, 0.02, 0.02, 0.02, 2e-5, 2e-4])
#: A clearly different second-stage pose costing at most this much more than the best also
#: seeds the second search (1.3 gave the same answers on the benchmarks for 10 ms more).
RESEED_RIVAL_RATIO = 1.1
#: Rotation (rad) beyond which two fitted poses count as different solutions.
DISTINCT = np.deg2rad(10.0)
#: Samples of the arc angle for the nearest-point search before Newton polishing.
N_THETA_GRID = 24


class NeedleNotFound(Exception):
    """The needle is not visible enough to estimate its pose; ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class MaskView:
    """A needle mask (bool) of one eye, possibly a crop whose top-left pixel is ``origin``.

    ``free_dt`` (optional, a crop at ``free_origin``) holds, for pixels that certainly show
    no needle (tissue or cavity colour, not an occluder), the distance in pixels to the nearest
    pixel that might (0 elsewhere): the model's centre-line is pulled out of free space, which
    pins an arc whose ends are hidden without penalising occluded parts.

    ``occluder`` (optional, same shape as ``mask``) marks pixels of something in front that
    could hide the needle (grey metal that is not needle): where the mask meets it, its
    boundary is where the needle is cut off from view, not the wire's outline, so those edge
    points are left out of the fit.
    """

    mask: np.ndarray
    origin: tuple[int, int] = (0, 0)
    free_dt: np.ndarray | None = None
    free_origin: tuple[int, int] = (0, 0)
    occluder: np.ndarray | None = None


#: Centre-line samples per eye for the free-space term, and its weight.
N_FREE_SAMPLES = 24
FREE_WEIGHT = 1.0


def _eye_transforms(stereo: StereoCameraModel) -> tuple[np.ndarray, np.ndarray]:
    """T_eye_left for the left and right cameras (poses are fitted in the left frame)."""
    T_world_left = stereo.left.T_world_cam
    return tuple(invert(cam.T_world_cam) @ T_world_left for cam in (stereo.left, stereo.right))


def _project_model_points(cam, T_eye_left: np.ndarray, T: np.ndarray, pts: np.ndarray):
    """Pixels (u, v), each (K, P), of needle-frame points ``pts`` under poses T (K, 4, 4)."""
    M = T_eye_left[None] @ T  # (K, 4, 4) needle in this eye
    p = pts @ M[:, :3, :3].transpose(0, 2, 1) + M[:, None, :3, 3]
    z = np.maximum(p[..., 2], 1e-6)
    return cam.fx * p[..., 0] / z + cam.cx, cam.fy * p[..., 1] / z + cam.cy


class FreeSpaceTerm:
    """Residuals (K, 2·M): free-space distance at the model's projected centre-line points."""

    #: Also used in the final polish on every edge point.
    polish = True

    def __init__(self, stereo: StereoCameraModel, model: NeedleModel, views) -> None:
        self.pts = model.centerline(N_FREE_SAMPLES)
        self.eyes = []
        cams = (stereo.left, stereo.right)
        for cam, T_el, v in zip(cams, _eye_transforms(stereo), views, strict=True):
            if v.free_dt is not None:
                self.eyes.append((cam, T_el, v.free_dt.astype(np.float64), v.free_origin))

    def __bool__(self) -> bool:
        return bool(self.eyes)

    def __call__(self, T: np.ndarray) -> np.ndarray:
        out = []
        for cam, T_el, dt, (x0, y0) in self.eyes:
            u, v = _project_model_points(cam, T_el, T, self.pts)
            out.append(FREE_WEIGHT * _bilinear(dt, u - x0, v - y0))
        return np.concatenate(out, -1)

    def column_weights(self, n_edge: int) -> np.ndarray:
        """Each centre-line sample counts as one edge point."""
        return np.ones(N_FREE_SAMPLES * len(self.eyes))


#: Share of the objective given to the keypoint prior (all its keypoints together), relative
#: to all the edge points together.
END_PRIOR_SHARE = 0.02


class EndPriorTerm:
    """Residuals (K, M): pixel distance from each confident keypoint to the nearer of the
    model's projected ends (base and tip look alike to the outline, so either may take it).

    The outline alone cannot tell where along a partly hidden arc the visible piece lies; a
    keypoint the network is sure of says which basin is right. Keypoints can be several
    pixels off, so the term only guides the search: the final solutions are polished and
    chosen on the outline alone (1080p unoccluded with the term in the polish: 0.32 mm /
    1.2 deg mean, against 0.17 mm / 0.2 deg without).
    """

    polish = False

    def __init__(self, stereo: StereoCameraModel, model: NeedleModel, keypoints) -> None:
        """``keypoints`` = (left (M, 2), right (M', 2)) pixel arrays (either may be empty)."""
        self.ends = np.stack([model.base, model.tip])
        self.eyes = []
        cams = (stereo.left, stereo.right)
        for cam, T_el, kp in zip(cams, _eye_transforms(stereo), keypoints, strict=True):
            kp = np.asarray(kp, float).reshape(-1, 2)
            if len(kp):
                self.eyes.append((cam, T_el, kp))
        self.n = sum(len(kp) for _, _, kp in self.eyes)

    def __bool__(self) -> bool:
        return self.n > 0

    def __call__(self, T: np.ndarray) -> np.ndarray:
        out = []
        for cam, T_el, kp in self.eyes:
            uv = np.stack(_project_model_points(cam, T_el, T, self.ends), -1)  # (K, 2, 2)
            d = np.linalg.norm(uv[:, None, :, :] - kp[None, :, None, :], axis=-1)  # (K, M, 2)
            out.append(d.min(-1))
        return np.concatenate(out, -1)

    def column_weights(self, n_edge: int) -> np.ndarray:
        """All keypoints together weigh END_PRIOR_SHARE of all the edge points."""
        return np.full(self.n, END_PRIOR_SHARE * n_edge / self.n)


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear samples of img at (u, v); 0 outside."""
    h, w = img.shape
    inside = (u >= 0) & (v >= 0) & (u <= w - 1) & (v <= h - 1)  # False for NaN too
    uc = np.clip(np.nan_to_num(u), 0, w - 1.001)
    vc = np.clip(np.nan_to_num(v), 0, h - 1.001)
    i0, j0 = vc.astype(int), uc.astype(int)
    fy, fx = vc - i0, uc - j0
    val = (
        img[i0, j0] * (1 - fx) * (1 - fy)
        + img[i0, j0 + 1] * fx * (1 - fy)
        + img[i0 + 1, j0] * (1 - fx) * fy
        + img[i0 + 1, j0 + 1] * fx * fy
    )
    return np.where(inside, val, 0.0)


def edge_points(view: MaskView) -> np.ndarray:
    """Sub-pixel edge points (N, 2) in full-image (u, v): midpoints of in/out 4-neighbour pairs
    (pairs touching an ``occluder`` pixel are left out)."""
    m = np.asarray(view.mask, bool)
    x0, y0 = view.origin
    occ = np.zeros_like(m) if view.occluder is None else np.asarray(view.occluder, bool)
    pts = []
    dh = (m[:, 1:] != m[:, :-1]) & ~(occ[:, 1:] | occ[:, :-1])
    v, u = np.nonzero(dh)
    pts.append(np.stack([u + 0.5, v.astype(float)], 1))
    dv = (m[1:, :] != m[:-1, :]) & ~(occ[1:, :] | occ[:-1, :])
    v, u = np.nonzero(dv)
    pts.append(np.stack([u.astype(float), v + 0.5], 1))
    out = np.concatenate(pts, 0)
    return out + np.array([x0, y0], float)


@dataclass
class EdgeRays:
    """Edge rays of both eyes in the left camera frame, with their pixel scale data."""

    origins: np.ndarray  # (N, 3)
    dirs: np.ndarray  # (N, 3) unit
    dz: np.ndarray  # (N,) z of the direction in its own eye frame
    focal: np.ndarray  # (N,) focal length of its eye (px)
    eye: np.ndarray  # (N,) 0 left, 1 right

    def subset(self, idx: np.ndarray) -> EdgeRays:
        return EdgeRays(
            self.origins[idx], self.dirs[idx], self.dz[idx], self.focal[idx], self.eye[idx]
        )

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
        step = np.clip(_newton_step(theta, o, d, od, r), -(hi - lo) / grid, (hi - lo) / grid)
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
    f, qd = _arc_f(theta, o, d, model.radius)
    dist = np.sqrt(np.maximum(f, 0.0))
    depth = qd * rays.dz[None]
    r = (dist - model.wire_radius) * rays.focal[None] / np.where(depth > 1e-6, depth, np.nan)
    return r, theta


def edge_jacobian(
    T: np.ndarray, dT: np.ndarray, rays: EdgeRays, model: NeedleModel, theta: np.ndarray
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
    r = model.radius
    P = (r * np.cos(theta), r * np.sin(theta))
    a = (P[0] - o[0], P[1] - o[1], -o[2])
    qd = a[0] * d[0] + a[1] * d[1] + a[2] * d[2]
    e = [a[i] - qd * d[i] for i in range(3)]
    dist = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    k = rays.focal[None] / (qd * rays.dz[None])
    inv = 1.0 / np.maximum(dist, 1e-12)
    along = (dist - model.wire_radius) / qd
    g = [k * (e[i] * inv - along * d[i]) for i in range(3)]
    H = np.stack([g[i] * P[n] for i in range(3) for n in range(2)] + g, -1)  # (K, N, 9)
    R = T[:, :3, :3]
    A = np.einsum("kmi,kjmn->kjin", R, dT[..., :3, :2]).reshape(*dT.shape[:2], 6)
    b = np.einsum("kmi,kjm->kji", R, dT[..., :3, 3])
    return np.concatenate([A, b], -1) @ H.transpose(0, 2, 1)


#: Robust losses of the fit: Cauchy (outliers grow logarithmically; a wide basin for the
#: search) and Geman-McClure (outliers cost a constant; the pose that explains the most edge
#: points tightly wins, however a few stray mask pixels lie).
LOSSES = ("cauchy", "geman_mcclure")


def _irls_weights(r: np.ndarray, sigma: float, loss: str) -> np.ndarray:
    """IRLS weights ψ(r)/r of the loss."""
    q = 1.0 + (r / sigma) ** 2
    return 1.0 / q if loss == "cauchy" else 1.0 / q**2


def robust_cost(
    r: np.ndarray, sigma: float, weights: np.ndarray | None = None, loss: str = "cauchy"
) -> np.ndarray:
    """(Weighted) mean robust loss per start (inf where any residual is undefined)."""
    if loss not in LOSSES:
        raise ValueError(f"unknown loss {loss!r}; expected one of {LOSSES}")
    x2 = (r / sigma) ** 2
    c = 0.5 * sigma**2 * (np.log1p(x2) if loss == "cauchy" else x2 / (1.0 + x2))
    out = c.mean(-1) if weights is None else (c * weights).sum(-1) / weights.sum()
    return np.where(np.isfinite(out), out, np.inf)


def _pose_derivatives(x: np.ndarray, T: np.ndarray, cam, model: NeedleModel):
    """Poses stepped by FD_STEPS in each of the six parameters (K, 6, 4, 4) and the forward
    differences dT/dx (K, 6, 4, 4) at the poses T (K, 4, 4) of parameters x (K, 6)."""
    T6 = params_to_pose(x[:, None, :] + np.diag(FD_STEPS)[None], cam, model)
    return T6, (T6 - T[:, None]) / FD_STEPS[None, :, None, None]


def levenberg_marquardt(
    x: np.ndarray,
    rays: EdgeRays,
    stereo: StereoCameraModel,
    model: NeedleModel,
    iters: int,
    sigma: float,
    extra=None,
    loss: str = "cauchy",
) -> tuple[np.ndarray, np.ndarray]:
    """Batched robust LM over starts x (K, 6); returns (x, cost).

    ``extra`` (a term or a list of terms: ``term(T) -> (K, M)`` residuals in px, and
    ``term.column_weights(n_edge)``) adds residuals (free space, keypoint prior) to the edge
    residuals.
    """
    x = np.array(x, dtype=float)
    cam = stereo.left
    extras = [e for e in (extra if isinstance(extra, list | tuple) else [extra]) if e]
    colw = np.concatenate([np.ones(len(rays))] + [e.column_weights(len(rays)) for e in extras])

    def both(T, *a, **k):
        r, th = residuals(T, rays, model, *a, **k)
        return (np.concatenate([r] + [e(T) for e in extras], 1) if extras else r), th

    T = params_to_pose(x, cam, model)
    r, theta = both(T)
    cost = robust_cost(r, sigma, colw, loss)
    lam = np.full(len(x), 1e-2)
    n_edge = len(rays)
    for _ in range(iters):
        ok = np.isfinite(cost)
        if not ok.any():
            break
        w = colw * _irls_weights(r, sigma, loss)
        w = np.where(np.isfinite(w), w, 0.0)
        rr = np.where(np.isfinite(r), r, 0.0)
        # Pose derivatives by finite differences (cheap: 6 poses per start), residual
        # derivatives analytically for the edge points, by differences for the extra terms.
        T6, dT = _pose_derivatives(x, T, cam, model)
        J = edge_jacobian(T, dT, rays, model, theta)
        if extras:
            re = np.concatenate([e(T6.reshape(-1, 4, 4)) for e in extras], 1)
            re = re.reshape(len(x), 6, -1) - rr[:, None, n_edge:]
            J = np.concatenate([J, re / FD_STEPS[None, :, None]], 2)
        J = np.where(np.isfinite(J), J, 0.0)
        Jw = J * w[:, None, :]
        A = Jw @ J.transpose(0, 2, 1)
        g = (Jw @ rr[..., None])[..., 0]
        diag = np.einsum("kii->ki", A) + 1e-9
        Ad = A + lam[:, None, None] * np.einsum("ki,ij->kij", diag, np.eye(6))
        try:
            delta = -np.linalg.solve(Ad, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        xn = x + delta
        Tn = params_to_pose(xn, cam, model)
        rn, thn = both(Tn, theta_start=theta)
        cn = robust_cost(rn, sigma, colw, loss)
        better = cn < cost
        x[better], T[better], r[better], theta[better], cost[better] = (
            xn[better],
            Tn[better],
            rn[better],
            thn[better],
            cn[better],
        )
        lam = np.where(better, lam / 3.0, lam * 4.0)
        lam = np.clip(lam, 1e-7, 1e7)
    return x, cost


def pose_uncertainty(
    x: np.ndarray,
    rays: EdgeRays,
    stereo: StereoCameraModel,
    model: NeedleModel,
    sigma: float = 1.0,
    loss: str = "geman_mcclure",
) -> tuple[float, float]:
    """Predicted spread of a fitted pose: (angle std in degrees, arc-centre std in mm).

    The Gauss-Newton covariance s²·(Jᵀ W J)⁻¹ of the robust edge fit at parameters ``x``
    (W the loss's IRLS weights, s² their weighted residual variance), carried to the needle
    frame's rotation and origin. It is large where the seen outline leaves the pose free: a
    short, nearly straight visible piece fixes neither the arc's plane nor how it goes on behind
    an occluder. Neighbouring edge residuals are treated as independent (they are not), so it
    ranks views by how firmly they pin the pose; it is not a calibrated standard deviation.
    """
    cam = stereo.left
    x = np.asarray(x, dtype=float)[None]
    T = params_to_pose(x, cam, model)
    r, theta = residuals(T, rays, model)
    _, dT = _pose_derivatives(x, T, cam, model)
    J = edge_jacobian(T, dT, rays, model, theta)[0]
    r = r[0]
    ok = np.isfinite(r) & np.isfinite(J).all(0)
    if ok.sum() <= len(FD_STEPS):
        return float("inf"), float("inf")
    J, r = J[:, ok], r[ok]
    w = _irls_weights(r, sigma, loss)
    s2 = float((w * r * r).sum() / max(w.sum() - len(FD_STEPS), 1.0))
    cov = s2 * np.linalg.pinv((J * w) @ J.T)
    # Per parameter: the small rotation R0ᵀ dR (the axial vector of its skew part) and the
    # origin's shift.
    S = np.einsum("ji,kjl->kil", T[0, :3, :3], dT[0, :, :3, :3])
    J_rot = 0.5 * np.stack(
        [S[:, 2, 1] - S[:, 1, 2], S[:, 0, 2] - S[:, 2, 0], S[:, 1, 0] - S[:, 0, 1]]
    )
    J_pos = dT[0, :, :3, 3].T
    var_rot = max(float(np.trace(J_rot @ cov @ J_rot.T)), 0.0)
    var_pos = max(float(np.trace(J_pos @ cov @ J_pos.T)), 0.0)
    return float(np.degrees(np.sqrt(var_rot))), float(1e3 * np.sqrt(var_pos))


@dataclass(frozen=True)
class PoseFitResult:
    """A fitted needle pose with its evidence.

    ``rms_px`` is the RMS edge residual of inliers; ``inlier_fraction`` the share of edge points
    within 1.5 px of the model outline; ``ambiguity`` the cost of the best clearly different
    solution minus the chosen one's (small: tilt-mirror not resolved); ``angle_std_deg`` and
    ``position_std_mm`` how loosely the seen outline pins the pose (:func:`pose_uncertainty`).
    """

    T_cam_needle: np.ndarray
    T_world_needle: np.ndarray
    params: np.ndarray
    cost: float
    rms_px: float
    inlier_fraction: float
    n_edge_points: tuple[int, int]
    ambiguity: float
    candidates: list = field(default_factory=list, repr=False)
    angle_std_deg: float = float("nan")
    position_std_mm: float = float("nan")


def _rot_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


@dataclass
class PoseFitter:
    """Multi-start stereo fit of the needle pose to two masks (see module docstring)."""

    stereo: StereoCameraModel
    model: NeedleModel = field(default_factory=NeedleModel)
    n_psi: int = 12
    max_points_per_eye: int = 1200
    coarse_points_per_eye: int = 40
    mid_points_per_eye: int = 200
    n_keep: int = 12
    n_keep_alternative: int = 6
    min_edge_points: int = 12
    seed: int = 0
    #: LM iterations: all kept starts at σ = 3 px on the coarse subsample, the best
    #: ``n_second_stage`` (clearly different ones first, see ``_diverse``) at σ = 1 px on the
    #: mid one, then the best ``n_final`` clearly
    #: different solutions on every edge point. Many cheap first-stage starts find the right
    #: basin more often than few expensive ones (1080p occluded benchmark, cached scenes:
    #: success 0.465 -> 0.495 at 134 -> 119 ms with 12 + 6 starts and 8 second-stage ones).
    iterations: tuple[int, int, int] = (8, 8, 6)
    n_second_stage: int = 6
    #: Clearly different solutions (> DISTINCT apart) polished on every edge point.
    n_final: int = 2
    #: Starts of a second search from the best second-stage pose's own end pixels and depth
    #: (0: none), made when an end may be hidden (see ``fit``); as many again from a clearly
    #: different rival within RESEED_RIVAL_RATIO of its cost.
    #: 1080p occluded benchmark: success 0.690 -> 0.735 (seed 1000), 0.735 -> 0.785 (2000);
    #: the rival's seeds: 0.745 -> 0.750, 0.77 -> 0.70 mm, 9.6 -> 7.4 deg (seed 1000),
    #: 0.795 -> 0.800, 0.92 -> 0.89 mm (seed 2000), for about 3 ms; 12 instead of 6 starts
    #: (cached scenes, with the faster LM): 0.60 -> 0.49 mm, 6.1 -> 5.3 deg (seed 1000),
    #: success 0.850 -> 0.860, 0.63 -> 0.60 mm, 8.5 -> 8.1 deg (seed 2000), about 4 ms; 18:
    #: the same answers.
    n_reseed: int = 12
    #: Loss of that polish, whose cost also chooses between them (see LOSSES).
    final_loss: str = "geman_mcclure"
    #: Working distance (m) of the arc centre from the left camera: fits outside are rejected
    #: (a short visible piece is also explained by a much nearer, larger-looking needle).
    depth_range: tuple[float, float] = (0.03, 0.5)

    def fit(
        self,
        left: MaskView,
        right: MaskView,
        endpoints_left: tuple[np.ndarray, np.ndarray] | None = None,
        depth_hint: float | None = None,
        warm_start: np.ndarray | None = None,
        alternatives: Sequence[tuple[np.ndarray, np.ndarray] | None] = (),
        end_priors: tuple[np.ndarray, np.ndarray] | None = None,
        hidden_end: bool | None = None,
    ) -> PoseFitResult:
        """Fit; ``endpoints_left`` = (base uv, tip uv) in the left image; raise NeedleNotFound.

        ``end_priors`` (left, right pixel arrays) are keypoints the network is sure of: each
        pulls the nearer model end towards it (:class:`EndPriorTerm`). ``hidden_end`` says
        whether an end may be hidden (then the search is repeated from the best pose's own
        ends, ``n_reseed``); None: whenever there are ``alternatives``.

        ``alternatives`` are further end-pixel hypotheses (``None``: the mask's own farthest
        pair), searched over all depths; the best ``n_keep_alternative`` starts of each join
        the main hypothesis' in one batched fit, so a wrong keypoint or a hidden end costs one
        fit, not several.
        """
        rng = np.random.default_rng(self.seed)
        el, er = edge_points(left), edge_points(right)
        if len(el) < self.min_edge_points or len(er) < self.min_edge_points:
            raise NeedleNotFound(
                f"too few needle edge points (left {len(el)}, right {len(er)}, "
                f"need {self.min_edge_points} each)"
            )
        el = _subsample(el, self.max_points_per_eye, rng)
        er = _subsample(er, self.max_points_per_eye, rng)
        rays = edge_rays(self.stereo, el, er)
        nl = len(el)
        coarse = rays.subset(_balanced(nl, len(er), self.coarse_points_per_eye, rng))
        mid = rays.subset(_balanced(nl, len(er), self.mid_points_per_eye, rng))
        cam = self.stereo.left
        if endpoints_left is None and warm_start is not None:
            endpoints_left = tuple(end_pixels(cam, np.asarray(warm_start), self.model))
        terms = [FreeSpaceTerm(self.stereo, self.model, (left, right))]
        if end_priors is not None:
            terms.append(EndPriorTerm(self.stereo, self.model, end_priors))
        terms = [t for t in terms if t]
        coarse_w = np.concatenate(
            [np.ones(len(coarse))] + [t.column_weights(len(coarse)) for t in terms]
        )

        def best_starts(ends, hint, n: int) -> np.ndarray:
            """The n lowest-cost feasible starts (coarse edge subset) for one end hypothesis."""
            if ends is None:
                ends = _farthest_pair(el, rng)
            ub, ut = (np.asarray(e, float) for e in ends)
            st = self._starts(ub, ut, hint)
            T0 = params_to_pose(st, cam, self.model)
            r0, _ = residuals(T0, coarse, self.model, grid=12)
            r0 = np.concatenate([r0] + [t(T0) for t in terms], 1)
            c0 = robust_cost(r0, 3.0, coarse_w)
            order = np.argsort(c0)[:n]
            return st[[i for i in order if np.isfinite(c0[i])]]

        parts = [best_starts(endpoints_left, depth_hint, self.n_keep)]
        parts += [best_starts(e, None, self.n_keep_alternative) for e in alternatives]
        if warm_start is not None:
            parts.append(pose_to_params(np.asarray(warm_start)[None], cam, self.model))
        starts = np.concatenate(parts)
        if not len(starts):
            raise NeedleNotFound("no feasible pose hypothesis from the needle's end points")
        it1, it2, it3 = self.iterations
        x, c1 = levenberg_marquardt(starts, coarse, self.stereo, self.model, it1, 3.0, terms)
        if self.n_second_stage and len(x) > self.n_second_stage:
            x = x[self._diverse(x, c1, self.n_second_stage)]
        x, c = levenberg_marquardt(x, mid, self.stereo, self.model, it2, 1.0, terms)
        c = np.where(self._in_range(x), c, np.inf)
        if hidden_end is None:
            hidden_end = bool(alternatives)
        if self.n_reseed and hidden_end and np.isfinite(c).any():
            # The best pose's own end pixels and depth are sharper than any keypoint: a fresh
            # grid of plane angles there reaches the tilt-mirror twin the first starts missed.
            # A close rival's ends may be the right ones: it seeds the search too.
            seeds = self._diverse(x, c, 2)
            if len(seeds) > 1 and not c[seeds[1]] <= RESEED_RIVAL_RATIO * c[seeds[0]]:
                seeds = seeds[:1]
            st = []
            for T_best in params_to_pose(x[seeds], cam, self.model):
                ends = tuple(end_pixels(cam, T_best, self.model))
                st.append(best_starts(ends, float(T_best[2, 3]), self.n_reseed))
            st = np.concatenate(st)
            if len(st):
                y, cy = levenberg_marquardt(st, coarse, self.stereo, self.model, it1, 3.0, terms)
                y, cy = levenberg_marquardt(y, mid, self.stereo, self.model, it2, 1.0, terms)
                x = np.concatenate([x, y])
                c = np.concatenate([c, np.where(self._in_range(y), cy, np.inf)])
        if not np.isfinite(c).any():
            lo, hi = self.depth_range
            raise NeedleNotFound(
                f"no pose {1e3 * lo:.0f}-{1e3 * hi:.0f} mm from the camera explains the outline"
            )
        order = np.argsort(c)
        T_mid = params_to_pose(x[order], cam, self.model)
        finals, kept = [order[0]], [0]
        for j, k in enumerate(order[1:], 1):
            if len(finals) == self.n_final or not np.isfinite(c[k]):
                break
            if all(_rot_angle(T_mid[i, :3, :3], T_mid[j, :3, :3]) > DISTINCT for i in kept):
                finals.append(k)
                kept.append(j)
        polish = [t for t in terms if t.polish]
        xf, cf = levenberg_marquardt(
            x[finals], rays, self.stereo, self.model, it3, 1.0, polish, self.final_loss
        )
        cf = np.where(self._in_range(xf), cf, np.inf)
        if not np.isfinite(cf).any():
            raise NeedleNotFound("pose fit diverged")
        b = int(np.argmin(cf))
        T = params_to_pose(xf[b], cam, self.model)
        r, _ = residuals(T[None], rays, self.model)
        r = r[0]
        inl = np.abs(r) < 1.5
        rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else float("inf")
        amb = float(np.min(np.delete(cf, b)) - cf[b]) if len(cf) > 1 else float("inf")
        ang_std, pos_std = pose_uncertainty(
            xf[b], rays, self.stereo, self.model, 1.0, self.final_loss
        )
        return PoseFitResult(
            T_cam_needle=T,
            T_world_needle=cam.T_world_cam @ T,
            params=xf[b],
            cost=float(cf[b]),
            rms_px=rms,
            inlier_fraction=float(inl.mean()),
            n_edge_points=(len(el), len(er)),
            ambiguity=amb,
            candidates=[params_to_pose(xx, cam, self.model) for xx in xf],
            angle_std_deg=ang_std,
            position_std_mm=pos_std,
        )

    def _diverse(self, x: np.ndarray, cost: np.ndarray, n: int) -> np.ndarray:
        """Indices of n low-cost rows, clearly different solutions first (> DISTINCT apart or
        with the centre > a radius apart): many starts fall into one basin, and copies of it
        would crowd out the next-best basin (often the right one when an end is hidden)."""
        order = [int(i) for i in np.argsort(cost) if np.isfinite(cost[i])]
        if not order:
            return np.argsort(cost)[:n]
        T = params_to_pose(x[order], self.stereo.left, self.model)
        picked: list[int] = []
        for j in range(len(order)):
            if len(picked) == n:
                break
            if all(
                _rot_angle(T[j, :3, :3], T[k, :3, :3]) > DISTINCT
                or np.linalg.norm(T[j, :3, 3] - T[k, :3, 3]) > self.model.radius
                for k in picked
            ):
                picked.append(j)
        rest = [j for j in range(len(order)) if j not in picked]
        picked += rest[: n - len(picked)]
        return np.array([order[j] for j in picked], int)

    def _in_range(self, x: np.ndarray) -> np.ndarray:
        """Which parameter rows put the arc centre within ``depth_range`` of the camera."""
        z = params_to_pose(x, self.stereo.left, self.model)[:, 2, 3]
        return (z >= self.depth_range[0]) & (z <= self.depth_range[1])

    def _starts(self, ub: np.ndarray, ut: np.ndarray, depth_hint: float | None) -> np.ndarray:
        """Start parameters over depths × both chord roots × psi."""
        if depth_hint is not None and np.isfinite(depth_hint) and depth_hint > 0:
            depths = depth_hint * np.array([0.8, 0.9, 1.0, 1.1, 1.25])
        else:
            depths = np.geomspace(0.05, 0.3, 12)
        phis = phi_from_base_depth(
            np.broadcast_to(ub, (len(depths), 2)),
            np.broadcast_to(ut, (len(depths), 2)),
            depths,
            self.stereo.left,
            self.model,
        ).ravel()
        phis = np.unique(np.round(phis, 6))
        psis = np.linspace(-np.pi, np.pi, self.n_psi, endpoint=False) + np.pi / self.n_psi
        P, S = np.meshgrid(phis, psis, indexing="ij")
        n = P.size
        return np.concatenate(
            [
                np.broadcast_to(ub, (n, 2)),
                np.broadcast_to(ut, (n, 2)),
                P.reshape(-1, 1),
                S.reshape(-1, 1),
            ],
            1,
        )


def _subsample(pts: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    if len(pts) <= n:
        return pts
    return pts[np.sort(rng.choice(len(pts), n, replace=False))]


def _balanced(nl: int, nr: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of up to n points from each eye (left first in the ray arrays)."""
    a = np.sort(rng.choice(nl, min(n, nl), replace=False))
    b = nl + np.sort(rng.choice(nr, min(n, nr), replace=False))
    return np.concatenate([a, b])


def mask_ends(view: MaskView, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The mask's two mutually farthest edge points (full-image px): the visible arc's ends."""
    pts = edge_points(view)
    if len(pts) < 2:
        raise NeedleNotFound("the needle mask has no ends (fewer than two edge points)")
    return _farthest_pair(pts, np.random.default_rng(seed))


def _farthest_pair(pts: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The two mutually farthest edge points: the arc's ends (identity unknown)."""
    p = _subsample(pts, 400, rng)
    d = np.sum((p[:, None] - p[None]) ** 2, -1)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return p[i], p[j]
