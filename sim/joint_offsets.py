"""The hidden joint-offset model of DESIGN.md §5: an encoder bias on joints 1-3.

The arm is driven to ``q_cmd + Δq`` but reports ``q_actual − Δq``: the bias never shows in
joint readings (measured equals commanded once the servo settles) and only shows in images.
"""

from __future__ import annotations

import numpy as np


class JointOffset:
    """A fixed bias Δq (6 values; only joints 1-3 may be non-zero)."""

    def __init__(self, delta_q):
        dq = np.asarray(delta_q, dtype=float).reshape(6)
        if np.any(dq[3:] != 0.0):
            raise ValueError("joint offsets apply to joints 1-3 only; joints 4-6 must be zero")
        self._dq = dq

    @property
    def delta_q(self) -> np.ndarray:
        """Δq (ground truth: only ``suture_bt.sim.ground_truth`` hands it out)."""
        return self._dq.copy()

    def actuated(self, q_cmd) -> np.ndarray:
        """Where the joints are driven when q_cmd is commanded."""
        return np.asarray(q_cmd, dtype=float) + self._dq

    def measured(self, q_actual) -> np.ndarray:
        """What the encoders report for the true joint positions q_actual."""
        return np.asarray(q_actual, dtype=float) - self._dq
