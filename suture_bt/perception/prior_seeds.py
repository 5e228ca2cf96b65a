"""Starts for the pose fit from a held needle's priors: circles through the holder's pinch
point with their plane across its jaws, the needle placed along them where it may be held.

For a needle whose seen piece alone leaves the pose loose (or whose mirror twin the image
search finds first), the priors alone say much of the pose; these starts let the fit begin
there (:mod:`fit_attempts`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_prior import (
    AcrossJawsPrior,
    HeldPrior,
    NeedlePrior,
    PortPrior,
)

#: Seeds per held needle: turns of the radius at the pinch point about the needle's normal,
#: and places of the pinch along the arc (from the tip to the base).
SEED_TURNS, SEED_PLACES = 16, 5


def seed_poses(priors: Sequence[NeedlePrior], model: NeedleModel) -> np.ndarray:
    """World poses (K, 4, 4) that agree with a held-by prior and the across-the-jaws face
    of the same arm: the fit's starts for a needle whose seen piece alone leaves it loose or
    whose twins the image search finds first (empty: the priors do not pin a needle).

    The circle passes through the pinch point with its normal along the face; what is left
    free, the radius's turn at the pinch and where along the arc the jaw holds it, is
    sampled (SEED_TURNS × SEED_PLACES; the held place and its swap's when the prior gives
    it). With a port prior the turns are those whose circle
    passes nearest the port as well."""
    held = {p.arm: p for p in priors if isinstance(p, HeldPrior)}
    faces = [p for p in priors if isinstance(p, AcrossJawsPrior) and p.arm in held]
    if not faces:
        return np.zeros((0, 4, 4))
    jaws, pinch = faces[0], np.asarray(held[faces[0].arm].pinch_point, float)
    z = np.asarray(jaws.face, float) / np.linalg.norm(jaws.face)
    e0 = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    e0 /= np.linalg.norm(e0)
    e1 = np.cross(z, e0)
    turns = np.linspace(0.0, 2 * np.pi, SEED_TURNS, endpoint=False)
    ports = [p for p in priors if isinstance(p, PortPrior)]
    if ports:
        through = _turns_through(ports[0].point - pinch, e0, e1, model.radius)
        if len(through):
            turns = through
        else:  # the port lies beyond the circle's reach: the nearest turns
            centres = pinch - model.radius * (
                np.cos(turns)[:, None] * e0 + np.sin(turns)[:, None] * e1
            )
            miss = [
                abs(np.linalg.norm(np.cross(ports[0].point - c, z)) - model.radius) for c in centres
            ]
            turns = turns[np.argsort(miss)[:4]]
    held_at = held[faces[0].arm].arc_angle
    if held_at is None:
        places = np.linspace(model.tip_angle, model.base_angle, SEED_PLACES + 2)[1:-1]
    else:  # where the grasp holds it (and the swap's place: the fit's ends are not told yet)
        places = np.array([held_at, model.swapped_angle(held_at)])
    # Every (turn, place) at once: the radial (centre → pinch, world) and, the pinch at arc
    # angle a, the needle's x turned by -a from it.
    psi, a = (v.ravel() for v in np.meshgrid(turns, places, indexing="ij"))
    radial = np.cos(psi)[:, None] * e0 + np.sin(psi)[:, None] * e1
    x = np.cos(-a)[:, None] * radial + np.sin(-a)[:, None] * np.cross(z, radial)
    out = np.zeros((len(psi), 4, 4))
    out[:, :3, 0], out[:, :3, 1], out[:, :3, 2] = x, np.cross(z, x), z
    out[:, :3, 3] = pinch - model.radius * radial
    out[:, 3, 3] = 1.0
    return out


def _turns_through(q: np.ndarray, e0: np.ndarray, e1: np.ndarray, radius: float) -> np.ndarray:
    """Turns ψ (0-2) of the radial at the pinch whose circle (in the plane e0, e1 through the
    pinch, centre at -radius·(cos ψ e0 + sin ψ e1)) passes through the point ``q`` (from the
    pinch) projected onto that plane: |q + radius·u(ψ)| = radius."""
    a, b = float(q @ e0), float(q @ e1)
    d = np.hypot(a, b)
    if d < 1e-9 or d > 2 * radius:
        return np.zeros(0)
    phi, half = np.arctan2(b, a), np.arccos(-d / (2 * radius))
    return np.array([phi + half, phi - half])
