"""Where the pose fit starts and which of its poses it carries on: a grid of starts over
depths, chord roots and the arc's turn about its chord, a pick of clearly different
low-cost poses so copies of one basin do not crowd out the next (often the right one), and
how far a fitted pose's ends moved from the end hypotheses it started from."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_projection import params_to_pose, phi_from_base_depth

#: Rotation (rad) beyond which two fitted poses count as different solutions.
DISTINCT = np.deg2rad(10.0)


def rot_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle (rad) of the rotation between two rotation matrices."""
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def start_params(
    ub: np.ndarray, ut: np.ndarray, depth_hint: float | None, cam, model: NeedleModel, n_psi: int
) -> np.ndarray:
    """Start parameters for end pixels ``ub``, ``ut`` (left image) over depths (about
    ``depth_hint`` when given, else 5-30 cm) × both chord roots × ``n_psi`` turns psi."""
    if depth_hint is not None and np.isfinite(depth_hint) and depth_hint > 0:
        depths = depth_hint * np.array([0.8, 0.9, 1.0, 1.1, 1.25])
    else:
        depths = np.geomspace(0.05, 0.3, 12)
    phis = phi_from_base_depth(
        np.broadcast_to(ub, (len(depths), 2)),
        np.broadcast_to(ut, (len(depths), 2)),
        depths,
        cam,
        model,
    ).ravel()
    phis = np.unique(np.round(phis, 6))
    psis = np.linspace(-np.pi, np.pi, n_psi, endpoint=False) + np.pi / n_psi
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


def diverse(x: np.ndarray, cost: np.ndarray, n: int, cam, model: NeedleModel) -> np.ndarray:
    """Indices of n low-cost rows, clearly different solutions first (> DISTINCT apart or
    with the centre > a radius apart): many starts fall into one basin, and copies of it
    would crowd out the next-best basin (often the right one when an end is hidden)."""
    order = [int(i) for i in np.argsort(cost) if np.isfinite(cost[i])]
    if not order:
        return np.argsort(cost)[:n]
    T = params_to_pose(x[order], cam, model)
    picked: list[int] = []
    for j in range(len(order)):
        if len(picked) == n:
            break
        if all(
            rot_angle(T[j, :3, :3], T[k, :3, :3]) > DISTINCT
            or np.linalg.norm(T[j, :3, 3] - T[k, :3, 3]) > model.radius
            for k in picked
        ):
            picked.append(j)
    rest = [j for j in range(len(order)) if j not in picked]
    picked += rest[: n - len(picked)]
    return np.array([order[j] for j in picked], int)


def ends_moved(ends: np.ndarray, tried: Sequence) -> float:
    """How far (px) the end pixels ``ends`` (2, 2) lie from the nearest of the end hypotheses
    ``tried`` (the farther end of the pair, either way round; inf: none tried)."""
    if not len(tried):
        return float("inf")
    h = np.asarray(tried, float)  # (H, 2 ends, 2)
    same = np.linalg.norm(h - ends[None], axis=2).max(1)
    swapped = np.linalg.norm(h - ends[None, ::-1], axis=2).max(1)
    return float(np.minimum(same, swapped).min())
