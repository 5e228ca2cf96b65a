"""Joint-offset compensation: map between true joints and the arm's command/measurement space.

Offset model (DESIGN.md §5): an unknown bias Δq on joints 1-3; the arm is driven to
q_actual = q_cmd + Δq and reports q_meas = q_actual − Δq. Given an estimate Δq̂:

- desired side: to put the TRUE joints at q_d, command q_cmd = q_d − Δq̂, since then
  q_actual = q_d − Δq̂ + Δq = q_d when Δq̂ = Δq;
- measured side: the best estimate of the TRUE joints is q̂_actual = q_meas + Δq̂, since
  q_meas + Δq = q_actual.

A loop comparing q_d with q_meas + Δq̂ and sending (its output − Δq̂) is therefore the
seed's Fig. 1a, "Δq̂ applied to both the desired and the measured joints": the same loop run in
the arm's own space compares q_d − Δq̂ with q_meas. With Δq̂ = 0 both maps are the identity.
"""

from __future__ import annotations

import numpy as np

from suture_bt.kinematics import NUM_JOINTS

#: The offset acts on joints 1-3 (outer yaw, outer pitch, insertion).
OFFSET_JOINTS = 3


def full_offset(offset) -> np.ndarray:
    """A 6-vector offset from a 3-vector (joints 1-3) or a 6-vector whose joints 4-6 are 0."""
    d = np.asarray(offset, dtype=float).reshape(-1)
    if d.shape[0] == OFFSET_JOINTS:
        return np.r_[d, np.zeros(NUM_JOINTS - OFFSET_JOINTS)]
    if d.shape[0] == NUM_JOINTS:
        if np.any(d[OFFSET_JOINTS:] != 0):
            raise ValueError("the joint-offset model only covers joints 1-3")
        return d.copy()
    raise ValueError(f"offset must have 3 (joints 1-3) or 6 values, got {d.shape[0]}")


def command_for_true(q_true, offset) -> np.ndarray:
    """Arm command that puts the true joints at ``q_true`` when ``offset`` is the true Δq."""
    return np.asarray(q_true, dtype=float) - full_offset(offset)


def true_from_measured(q_meas, offset) -> np.ndarray:
    """Estimate of the true joints from the arm's reading, given the offset estimate."""
    return np.asarray(q_meas, dtype=float) + full_offset(offset)
