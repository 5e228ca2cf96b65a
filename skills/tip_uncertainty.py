"""How far an arm's tip may be from where its kinematics put it, before calibration.

The hidden joint offset is bounded by the task (SRC: 5°, 5°, 5 mm on joints 1-3); until the
arm is calibrated, its tip may be anywhere the bound allows. Used wherever a margin must cover
that: the held-by test of a localised needle, the clearance kept above the tissue.
"""

from __future__ import annotations

import numpy as np

from suture_bt.calibration.calibration_pose import offset_box_points
from suture_bt.kinematics import forward_kinematics


def tip_displacements(q: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Tip displacements (K×3, base frame, m) that the hidden ``offsets`` (K×3 on joints 1-3)
    cause at joints ``q``."""
    q = np.asarray(q, dtype=float)
    tip = forward_kinematics(q)[:3, 3]
    out = np.empty((len(offsets), 3))
    for i, dq in enumerate(offsets):
        q2 = q.copy()
        q2[:3] += dq
        out[i] = forward_kinematics(q2)[:3, 3] - tip
    return out


def offset_displacements(q: np.ndarray, levels: int = 3) -> np.ndarray:
    """Tip displacements (K×3, base frame, m) that hidden offsets on a ``levels``³ grid over
    the task's bound cause at joints ``q``, and the zero offset's (none). The tip moves
    nearly linearly over the box, so its corners (``levels`` = 2) bound the rest."""
    return np.vstack([np.zeros(3), tip_displacements(q, offset_box_points(levels))])


def worst_offset_displacement(q: np.ndarray) -> float:
    """Largest tip displacement (m) a hidden offset within the task's bound can cause at
    joints ``q`` (the corners of the bound box; the tip moves monotonically between them)."""
    return float(np.linalg.norm(tip_displacements(q, offset_box_points(2)), axis=1).max())


def tip_margin(arm) -> float:
    """0 for a calibrated arm, else the worst displacement at its present joints (m)."""
    return 0.0 if arm.calibrated else worst_offset_displacement(arm.servo.estimated_jp())
