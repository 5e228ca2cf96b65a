"""The seed's needle-pose parameterisation and an exact rasteriser of the needle tube.

Parameters (vectorised, shape (..., 6)): the base and tip pixels in the left image
(u_b, v_b, u_t, v_t) and two angles. ``phi`` is the angle at the base between the ray back to
the camera and the chord towards the tip; it fixes both end depths through the chord length
(law of sines). ``psi`` rotates the arc plane about the chord: psi = 0 puts the arc's bulge
across the line of sight, ±π/2 along it; psi and −psi are the tilt-mirror pair.
Poses are ``T_cam_needle`` in the left camera's OpenCV frame.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import CameraModel
from suture_bt.perception.compiled import kernel


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(np.sum(v * v, -1, keepdims=True))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (np.cross has a large per-call overhead)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], -1)


def pixel_rays(cam: CameraModel, uv: np.ndarray) -> np.ndarray:
    """Unit ray directions (camera frame) through pixels (..., 2)."""
    uv = np.asarray(uv, dtype=float)
    d = np.stack(
        [(uv[..., 0] - cam.cx) / cam.fx, (uv[..., 1] - cam.cy) / cam.fy, np.ones(uv.shape[:-1])],
        -1,
    )
    return _unit(d)


def project_cam(cam: CameraModel, points_cam: np.ndarray) -> np.ndarray:
    """Pixels (..., 2) of camera-frame points (..., 3)."""
    p = np.asarray(points_cam, dtype=float)
    return np.stack(
        [cam.fx * p[..., 0] / p[..., 2] + cam.cx, cam.fy * p[..., 1] / p[..., 2] + cam.cy], -1
    )


@functools.lru_cache(maxsize=8)
def _needle_frame_basis(model: NeedleModel) -> tuple[np.ndarray, float, float]:
    """Fixed basis [chord, bulge, normal] of the needle frame, chord length, centre-to-chord."""
    b, t = model.base, model.tip
    chord = float(np.linalg.norm(t - b))
    e1 = (t - b) / chord
    mid = 0.5 * (b + t)
    h = float(np.linalg.norm(mid))
    u = mid / h
    return np.stack([e1, u, np.cross(e1, u)], 1), chord, h


def params_to_pose(params: np.ndarray, cam: CameraModel, model: NeedleModel) -> np.ndarray:
    """Poses T_cam_needle (..., 4, 4) from parameters (..., 6); NaN where infeasible.

    The fit calls this thousands of times on small batches, where numpy's per-call overhead
    would dominate: a compiled loop over the rows (:func:`_poses_from_params`).
    """
    x = np.asarray(params, dtype=float)
    Bn, chord, h = _needle_frame_basis(model)
    flat = np.ascontiguousarray(x.reshape(-1, 6))
    out = _poses_from_params(flat, cam.fx, cam.fy, cam.cx, cam.cy, Bn, chord, h)
    return out.reshape(x.shape[:-1] + (4, 4))


@kernel()
def _poses_from_params(x, fx, fy, cx, cy, Bn, chord, h):
    """Rows of :func:`params_to_pose`: the ends' rays, their depths by the law of sines from
    the chord, the arc plane turned by psi about the chord."""
    out = np.zeros((x.shape[0], 4, 4))
    v = np.empty((10, 3))  # working vectors
    rb, rt, B, T, e1, mid, n0, n1, u, w = v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9]
    Rc = np.empty((3, 3))
    for k in range(x.shape[0]):
        for ray, c in ((rb, 0), (rt, 2)):
            d0, d1 = (x[k, c] - cx) / fx, (x[k, c + 1] - cy) / fy
            n = math.sqrt(d0 * d0 + d1 * d1 + 1.0)
            ray[0], ray[1], ray[2] = d0 / n, d1 / n, 1.0 / n
        phi, psi = x[k, 4], x[k, 5]
        cg = min(max(rb[0] * rt[0] + rb[1] * rt[1] + rb[2] * rt[2], -1.0), 1.0)
        gamma = math.acos(cg)
        sg = max(math.sin(gamma), 1e-9)
        s = chord * math.sin(gamma + phi) / sg
        t = chord * math.sin(phi) / sg
        if not (s > 0 and t > 0 and phi > 0):
            out[k] = np.nan
            continue
        for i in range(3):
            B[i], T[i] = s * rb[i], t * rt[i]
            e1[i] = T[i] - B[i]
            mid[i] = 0.5 * (B[i] + T[i])
        e1 /= math.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
        m = mid / math.sqrt(mid[0] * mid[0] + mid[1] * mid[1] + mid[2] * mid[2])
        _cross_into(e1, m, n0)
        n0 /= math.sqrt(n0[0] * n0[0] + n0[1] * n0[1] + n0[2] * n0[2])
        _cross_into(e1, n0, n1)
        cp, sp = math.cos(psi), math.sin(psi)
        for i in range(3):
            u[i] = cp * n0[i] + sp * n1[i]
        _cross_into(e1, u, w)
        for i in range(3):
            Rc[i, 0], Rc[i, 1], Rc[i, 2] = e1[i], u[i], w[i]
        for i in range(3):
            for j in range(3):
                out[k, i, j] = Rc[i, 0] * Bn[j, 0] + Rc[i, 1] * Bn[j, 1] + Rc[i, 2] * Bn[j, 2]
            out[k, i, 3] = mid[i] - h * u[i]
        out[k, 3, 3] = 1.0
    return out


@kernel()
def _cross_into(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


def pose_to_params(T_cam_needle: np.ndarray, cam: CameraModel, model: NeedleModel) -> np.ndarray:
    """Inverse of :func:`params_to_pose` for one or more poses (..., 4, 4) → (..., 6)."""
    T = np.asarray(T_cam_needle, dtype=float)
    R, p = T[..., :3, :3], T[..., :3, 3]
    B = np.einsum("...ij,j->...i", R, model.base) + p
    Tp = np.einsum("...ij,j->...i", R, model.tip) + p
    Bn, _, _ = _needle_frame_basis(model)
    e1 = _unit(Tp - B)
    mid = 0.5 * (B + Tp)
    u = np.einsum("...ij,j->...i", R, Bn[:, 1])
    n0 = _unit(_cross(e1, _unit(mid)))
    n1 = _cross(e1, n0)
    psi = np.arctan2(np.sum(u * n1, -1), np.sum(u * n0, -1))
    phi = np.arccos(np.clip(np.sum(_unit(-B) * e1, -1), -1.0, 1.0))
    uvb, uvt = project_cam(cam, B), project_cam(cam, Tp)
    return np.concatenate([uvb, uvt, phi[..., None], psi[..., None]], -1)


def phi_from_base_depth(
    uv_base: np.ndarray, uv_tip: np.ndarray, depth: np.ndarray, cam: CameraModel, model: NeedleModel
) -> np.ndarray:
    """The two phi values (…, 2) that put the base at camera depth ``depth`` (tip nearer/farther).

    Where no chord of the right length joins the two rays, both roots fall back to the tip at
    the foot of the perpendicular.
    """
    _, chord, _ = _needle_frame_basis(model)
    rb = pixel_rays(cam, uv_base)
    rt = pixel_rays(cam, uv_tip)
    s = np.asarray(depth, dtype=float) / rb[..., 2]
    cg = np.clip(np.sum(rb * rt, -1), -1.0, 1.0)
    sg = np.sqrt(1 - cg**2)
    disc = np.sqrt(np.maximum(chord**2 - (s * sg) ** 2, 0.0))
    out = []
    for sign in (-1.0, 1.0):
        t = s * cg + sign * disc
        B = s[..., None] * rb
        Tp = np.maximum(t, 1e-6)[..., None] * rt
        e1 = _unit(Tp - B)
        out.append(np.arccos(np.clip(np.sum(_unit(-B) * e1, -1), -1.0, 1.0)))
    return np.stack(out, -1)


def transform_points(T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply a 4×4 transform to points (N, 3)."""
    return pts @ T[:3, :3].T + T[:3, 3]


def end_pixels(cam: CameraModel, T_cam_needle: np.ndarray, model: NeedleModel) -> np.ndarray:
    """Pixels (2, 2) of the needle's base and tip ends under pose T_cam_needle."""
    return project_cam(cam, transform_points(T_cam_needle, np.stack([model.base, model.tip])))


def rasterize_needle(
    cam: CameraModel, T_cam_needle: np.ndarray, model: NeedleModel, n_samples: int = 800
) -> np.ndarray:
    """Exact boolean mask (H, W): pixel-centre rays that pass within the wire radius.

    The needle is the union of spheres of the wire radius along the centre-line (a tube with
    hemispherical end caps, as the simulator's mesh). Brute force over a dilated candidate set
    of pixels; meant for tests and benchmarks, not the runtime path.
    """
    T = np.asarray(T_cam_needle, dtype=float)
    centre = transform_points(
        T, model.point_at(np.linspace(model.base_angle, model.tip_angle, n_samples))
    )
    mask = np.zeros((cam.height, cam.width), bool)
    if np.any(centre[:, 2] <= 1e-4):
        raise ValueError("needle behind or at the camera plane")
    uv = project_cam(cam, centre)
    w_px = cam.fx * model.wire_radius / centre[:, 2].min()
    cand = np.zeros((cam.height, cam.width), np.uint8)
    cv2.polylines(
        cand, [np.round(uv).astype(np.int32)], False, 1, thickness=int(2 * np.ceil(w_px) + 5)
    )
    vv, uu = np.nonzero(cand)
    if len(uu) == 0:
        return mask
    d = pixel_rays(cam, np.stack([uu, vv], 1).astype(float))
    best = np.full(len(uu), np.inf)
    for i in range(0, len(centre), 100):
        P = centre[i : i + 100]
        proj = d @ P.T
        dist2 = np.sum(P**2, 1)[None] - proj**2
        dist2[proj <= 0] = np.inf
        best = np.minimum(best, dist2.min(1))
    mask[vv, uu] = best <= model.wire_radius**2
    return mask
