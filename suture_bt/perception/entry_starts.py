"""Starts for a needle whose seen wire ends where it enters the known tissue.

The fit's starts put the needle's two ends at the outline's two ends. When the wire goes into
the tissue (a needle in a port, a tip stuck in the phantom) one outline end is not an end of
the needle but the point where it enters, and the arc goes on inside: no start has that shape,
and the search can settle on a pose that spans the seen piece with its whole arc (development
`occluded` in-port scene: the true pose cost 0.77× the answer, 18 mm / 180° off, and no start
reached it). The known tissue says where that point is: the outline end's line of sight meets
the tissue's surface there. These starts are circles of the needle's radius from a point on the
other end's line of sight through that entry point, over how much of the arc is seen and the
circle's turn about the chord, with either end of the needle outside. An end is taken as an
entry only where the other eye sees an end of the wire at that surface point too: the ray of
an end in front of the tissue meets the tissue far behind the needle, a point the other eye
sees elsewhere (without the check, such starts led the fit of a held needle whose end was 54 mm
from the eyes to a loose pose, refused with a 23° spread: development `held_start` #6).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_projection import pixel_rays
from suture_bt.perception.tissue_cut import TissueCut

#: Seen arc (deg) from the outside end to the entry point: the starts' chord lengths.
SEEN_ARC_DEG = (25.0, 45.0, 65.0, 85.0, 105.0)
#: Turns of the circle about its chord.
N_TURNS = 12
#: An entry point must project within this (px) of an end of the right eye's mask. A held
#: needle's end 54 mm away whose sight line met the tissue 13 mm behind it projected 5 px off
#: (development `held_start` #6 of seed 6173); the true entry of `occluded` #9, 0.4 px.
RIGHT_END_PX = 3.0


def surface_hit(cut: TissueCut, ray: np.ndarray) -> float:
    """Distance (m) along the unit ``ray`` from the camera (the cut's frame origin) to where it
    first enters the tissue (inf: never)."""
    best = np.inf
    g = cut.groups
    for k in range(len(g) - 1):
        P, N = cut.points[g[k] : g[k + 1]], cut.normals[g[k] : g[k + 1]]
        nd, nP = N @ ray, np.einsum("ij,ij->i", N, P)
        lo, hi = 0.0, np.inf
        for a, b in zip(nd, nP, strict=True):
            if abs(a) < 1e-12:
                if b <= 0.0:  # the ray runs outside this plane all along
                    lo, hi = np.inf, -np.inf
            elif a < 0.0:
                lo = max(lo, b / a)
            else:
                hi = min(hi, b / a)
        if lo <= hi:
            best = min(best, lo)
    return float(best)


def entry_starts(
    ends: tuple[np.ndarray, np.ndarray],
    cam,
    cut: TissueCut,
    model: NeedleModel,
    seen_there: Callable[[np.ndarray], bool] | None = None,
) -> np.ndarray:
    """Left-camera poses (K, 4, 4) that enter the tissue at one outline end's surface point
    and leave a needle end on the other end's line of sight (``ends``: two left-image pixels;
    each is tried as the entry, when ``seen_there`` (a left-camera point → whether the other
    eye sees an end of the wire there; None: not asked) says so). Empty when no end
    qualifies."""
    rays = pixel_rays(cam, np.stack([np.asarray(e, float) for e in ends]))
    out = []
    for entry, other in ((0, 1), (1, 0)):
        hit = surface_hit(cut, rays[entry])
        if not np.isfinite(hit) or (seen_there is not None and not seen_there(hit * rays[entry])):
            continue
        X, r = hit * rays[entry], rays[other]
        for seen in np.radians(SEEN_ARC_DEG):
            chord = 2.0 * model.radius * np.sin(0.5 * seen)
            for depth in _depths_at(X, r, chord):
                out.append(_circles(depth * r, X, model))
    if not out:
        return np.zeros((0, 4, 4))
    poses = np.concatenate(out)
    return np.concatenate([poses, model.swapped(poses)])


def seen_at_right_end(
    stereo, right_ends, reach_px: float = RIGHT_END_PX
) -> Callable[[np.ndarray], bool]:
    """:func:`entry_starts`' check: whether a left-camera point projects within ``reach_px``
    of either end of the right eye's mask (its two mutually farthest edge points)."""
    T = stereo.left.T_world_cam

    def seen(p: np.ndarray) -> bool:
        uv = stereo.right.project(T[:3, :3] @ p + T[:3, 3])[0]
        return min(float(np.linalg.norm(uv - e)) for e in right_ends) <= reach_px

    return seen


def _depths_at(X: np.ndarray, r: np.ndarray, chord: float) -> list[float]:
    """Distances t > 0 along the unit ray ``r`` with |t r − X| = chord."""
    b = float(r @ X)
    disc = b * b - (float(X @ X) - chord * chord)
    if disc < 0.0:
        return []
    s = np.sqrt(disc)
    return [t for t in (b - s, b + s) if t > 0.0]


def _circles(B: np.ndarray, X: np.ndarray, model: NeedleModel) -> np.ndarray:
    """Poses (N_TURNS, 4, 4) with the base at B and the arc's short way from it through X
    towards the tip, the circle turned about the chord BX."""
    e = (X - B) / np.linalg.norm(X - B)
    a = np.cross(e, [1.0, 0.0, 0.0] if abs(e[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(e, a)
    half = 0.5 * np.linalg.norm(X - B)
    h = np.sqrt(max(model.radius**2 - half * half, 0.0))
    turns = np.linspace(0.0, 2 * np.pi, N_TURNS, endpoint=False)
    w = np.cos(turns)[:, None] * a + np.sin(turns)[:, None] * b  # the centre's side
    C = 0.5 * (B + X) + h * w
    u, v = (B - C) / model.radius, (X - C) / model.radius
    z = -np.cross(u, v)  # base → tip turns the radius clockwise about z
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = -u  # the base sits at angle π
    out = np.zeros((N_TURNS, 4, 4))
    out[:, :3, 0], out[:, :3, 1], out[:, :3, 2] = x, np.cross(z, x), z
    out[:, :3, 3], out[:, 3, 3] = C, 1.0
    return out
