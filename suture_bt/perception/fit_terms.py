"""Extra terms of the pose fit beside the edge residuals: free space and confident keypoints."""

from __future__ import annotations

import math

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.compiled import kernel
from suture_bt.transforms import invert

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
            kp = np.ascontiguousarray(np.asarray(kp, float).reshape(-1, 2))
            if len(kp):
                self.eyes.append((cam, T_el, kp))
        self.n = sum(len(kp) for _, _, kp in self.eyes)

    def __bool__(self) -> bool:
        return self.n > 0

    def __call__(self, T: np.ndarray) -> np.ndarray:
        T = np.ascontiguousarray(T, dtype=np.float64)
        out = [
            _nearer_end_distances(T, T_el, cam.fx, cam.fy, cam.cx, cam.cy, self.ends, kp)
            for cam, T_el, kp in self.eyes
        ]
        return np.concatenate(out, -1)

    def column_weights(self, n_edge: int) -> np.ndarray:
        """All keypoints together weigh END_PRIOR_SHARE of all the edge points."""
        return np.full(self.n, END_PRIOR_SHARE * n_edge / self.n)


@kernel()
def _nearer_end_distances(T, T_eye_left, fx, fy, cx, cy, ends, kp):
    """(K, M) pixel distance from each keypoint (M, 2) to the nearer of the two model ends
    (2, 3, needle frame) projected into one eye under each pose T (K, 4, 4, left frame):
    the arithmetic of :func:`_project_model_points` per pose, compiled (in numpy the small
    arrays' call overhead was most of the fit's extra-term time)."""
    K, M = T.shape[0], kp.shape[0]
    out = np.empty((K, M))
    uv = np.empty((2, 2))
    for k in range(K):
        for e in range(2):
            # the end in the left frame (T), then in this eye's (T_eye_left)
            a, b, c = ends[e, 0], ends[e, 1], ends[e, 2]
            p0 = T[k, 0, 0] * a + T[k, 0, 1] * b + T[k, 0, 2] * c + T[k, 0, 3]
            p1 = T[k, 1, 0] * a + T[k, 1, 1] * b + T[k, 1, 2] * c + T[k, 1, 3]
            p2 = T[k, 2, 0] * a + T[k, 2, 1] * b + T[k, 2, 2] * c + T[k, 2, 3]
            E = T_eye_left
            x = E[0, 0] * p0 + E[0, 1] * p1 + E[0, 2] * p2 + E[0, 3]
            y = E[1, 0] * p0 + E[1, 1] * p1 + E[1, 2] * p2 + E[1, 3]
            z = max(E[2, 0] * p0 + E[2, 1] * p1 + E[2, 2] * p2 + E[2, 3], 1e-6)
            uv[e, 0] = fx * x / z + cx
            uv[e, 1] = fy * y / z + cy
        for m in range(M):
            d0 = math.hypot(uv[0, 0] - kp[m, 0], uv[0, 1] - kp[m, 1])
            d1 = math.hypot(uv[1, 0] - kp[m, 0], uv[1, 1] - kp[m, 1])
            out[k, m] = min(d0, d1)
    return out


#: The away term's residual (px) per degree short of its limit, and its column weight: steep
#: enough that the solver's results stay within half a degree of the limit.
AWAY_PX_PER_DEG = 0.3
AWAY_WEIGHT = 200.0


class AwayTerm:
    """Residual (K, 1): AWAY_PX_PER_DEG per degree that a pose's orientation lies nearer than
    ``min_deg`` to ``R_answer`` (0 beyond): a hinge that keeps a descent that far from an
    answer (:mod:`~.valley_probe`). Compiled in :mod:`~.lm_step` with the same arithmetic.
    Never one of a fit's own terms: the probe passes it to the solver beside the polish's."""

    def __init__(self, R_answer: np.ndarray, min_deg: float) -> None:
        self.R = np.ascontiguousarray(R_answer, dtype=np.float64)
        self.min_deg = float(min_deg)

    def __bool__(self) -> bool:
        return True

    def angles_deg(self, T: np.ndarray) -> np.ndarray:
        """Rotation angle (deg) of each pose (K, 4, 4) from ``R_answer``: from the trace of
        Rᵀ·R_pose, summed in :func:`away_angle`'s order."""
        trace = np.zeros(len(T))
        for i in range(3):
            for j in range(3):
                trace = trace + self.R[j, i] * T[:, j, i]
        c = np.minimum(np.maximum((trace - 1.0) / 2.0, -1.0), 1.0)
        return np.degrees(np.arccos(c))

    def __call__(self, T: np.ndarray) -> np.ndarray:
        short = np.maximum(self.min_deg - self.angles_deg(T), 0.0)
        return (AWAY_PX_PER_DEG * short)[:, None]

    def column_weights(self, n_edge: int) -> np.ndarray:
        return np.full(1, AWAY_WEIGHT)


@kernel()
def away_angle(R, T, k):
    """:meth:`AwayTerm.angles_deg` of pose ``T[k]``, compiled."""
    trace = 0.0
    for i in range(3):
        for j in range(3):
            trace = trace + R[j, i] * T[k, j, i]
    c = min(max((trace - 1.0) / 2.0, -1.0), 1.0)
    return math.degrees(math.acos(c))


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
