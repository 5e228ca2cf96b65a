"""Calibration poses (one per arm) and the numerical check that they identify the joint offset.

Why a fixed pose: at one known commanded pose the image of the 4 jaw keypoints is a function of
the hidden offset Δq (joints 1-3, DESIGN.md §5) alone; the regressor inverts that function,
which is only possible where it is injective and well conditioned over the whole offset box
(±5°, ±5°, ±5 mm). The poses below were found by a randomised search (joint space around the
arm's side of the image) that kept, for all 27 corners/mid-points of the box: every keypoint in
the left image with a 30 px margin, 25 mm or more in front of the lens, above the tissue
(z ≥ 76 mm; ≥ 84 mm over the ridge), keypoints ≥ 30 px apart, the wrist seen side-on; and
minimised the worst Cramér-Rao standard deviation of Δq for 1 px keypoint noise. (The search
used an earlier keypoint set, the wrist joint-axis points instead of the clevis corners;
:func:`uniqueness_report` re-checks the poses with the current keypoints, see
tests/test_calibration_pose.py: condition number ≤ 17, ≥ 4.6 px per degree/mm, worst
Cramér-Rao std ≤ 0.13°, 0.04°, 0.17 mm per px of noise.)
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from suture_bt.calibration.jaw_keypoints import (
    NUM_KEYPOINTS,
    keypoint_depths,
    keypoints_in_world,
    project_keypoints,
)
from suture_bt.calibration.scene_geometry import PSM_BASES, endoscope_model

#: Commanded joint vectors of the calibration poses (rad, rad, m, rad, rad, rad).
CALIBRATION_POSES = {
    "psm1": np.array([0.353, -0.188, 0.142, 0.975, -0.485, 0.228]),
    "psm2": np.array([-0.359, -0.179, 0.144, -0.989, -0.450, 0.254]),
}
#: Jaw angle at the calibration pose (rad): open, so the two jaw tips are distinct keypoints.
CALIBRATION_JAW = 0.8
#: Offset bounds (DESIGN.md §5) in SI units, and the unit used for reports: (1°, 1°, 1 mm).
OFFSET_BOUND = np.array([np.deg2rad(5.0), np.deg2rad(5.0), 0.005])
OFFSET_UNIT = np.array([np.deg2rad(1.0), np.deg2rad(1.0), 0.001])


def offset_box_points(levels: int = 3) -> np.ndarray:
    """A grid of offsets over the bound box (levels³ × 3, SI)."""
    axis = np.linspace(-1.0, 1.0, levels)
    return np.array(list(itertools.product(axis, axis, axis))) * OFFSET_BOUND


def actual_joints(q_cmd, offsets) -> np.ndarray:
    """True joints (N×6) of an arm commanded to q_cmd with hidden offsets (N×3)."""
    offsets = np.atleast_2d(offsets)
    q = np.tile(np.asarray(q_cmd, dtype=float), (offsets.shape[0], 1))
    q[:, :3] += offsets
    return q


def keypoint_jacobian(q_actual, T_world_base, camera, jaw: float = CALIBRATION_JAW) -> np.ndarray:
    """d(keypoint pixels)/d(joints 1-3), N×8×3, in px per offset unit (1°, 1°, 1 mm)."""
    q_actual = np.atleast_2d(q_actual)
    n = q_actual.shape[0]
    J = np.zeros((n, 2 * NUM_KEYPOINTS, 3))
    for j in range(3):
        step = np.zeros(6)
        step[j] = OFFSET_UNIT[j] * 1e-3
        plus = project_keypoints(q_actual + step, jaw, T_world_base, camera).reshape(n, -1)
        minus = project_keypoints(q_actual - step, jaw, T_world_base, camera).reshape(n, -1)
        J[:, :, j] = (plus - minus) / 2e-3
    return J


@dataclass(frozen=True)
class UniquenessReport:
    """Numerical evidence that Δq → keypoint pixels is injective and well conditioned."""

    arm: str
    max_condition_number: float
    min_singular_value: float  # px per (1° or 1 mm), worst over the grid
    worst_crb_std: np.ndarray  # (deg, deg, mm) per px of keypoint noise, worst over the grid
    min_margin_px: float  # smallest distance of a keypoint to the image border
    min_depth: float  # m, nearest keypoint to the camera
    pairs_checked: int  # sampled offset pairs whose keypoints are closer than tol_px
    max_offset_gap_of_close_pairs: float  # largest Δq distance (max-norm, units) among them
    tol_px: float
    epsilon: float

    @property
    def injective(self) -> bool:
        """No two sampled offsets more than ``epsilon`` apart have keypoints within ``tol_px``."""
        return self.max_offset_gap_of_close_pairs <= self.epsilon

    @property
    def ok(self) -> bool:
        return self.injective and self.min_margin_px > 0 and self.min_depth > 0


def uniqueness_report(
    arm: str,
    camera=None,
    *,
    grid_levels: int = 7,
    samples: int = 20000,
    tol_px: float = 3.0,
    epsilon: float = 1.0,
    seed: int = 0,
) -> UniquenessReport:
    """Check the calibration pose of ``arm``: Jacobian conditioning over a grid of offsets, and
    a global test that no two of ``samples`` random offsets more than ``epsilon`` (1° / 1 mm,
    max-norm) apart project to keypoint vectors closer than ``tol_px`` (Euclidean, 8-D)."""
    if arm not in CALIBRATION_POSES:
        raise ValueError(f"unknown arm {arm!r}; expected one of {sorted(CALIBRATION_POSES)}")
    camera = camera or endoscope_model().left
    T_base = PSM_BASES[arm]
    q_cmd = CALIBRATION_POSES[arm]
    grid = actual_joints(q_cmd, offset_box_points(grid_levels))
    J = keypoint_jacobian(grid, T_base, camera)
    sv = np.linalg.svd(J, compute_uv=False)
    cov = np.linalg.inv(np.einsum("nki,nkj->nij", J, J))
    crb = np.sqrt(np.einsum("nii->ni", cov)).max(0)
    pix = project_keypoints(grid, CALIBRATION_JAW, T_base, camera)
    margin = np.min(
        [pix[..., 0].min(), pix[..., 1].min(), camera.width - 1 - pix[..., 0].max()]
        + [camera.height - 1 - pix[..., 1].max()]
    )
    depth = keypoint_depths(grid, CALIBRATION_JAW, T_base, camera).min()
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-1.0, 1.0, (samples, 3)) * OFFSET_BOUND
    vec = project_keypoints(actual_joints(q_cmd, offsets), CALIBRATION_JAW, T_base, camera)
    pairs = cKDTree(vec.reshape(samples, -1)).query_pairs(tol_px, output_type="ndarray")
    gap = 0.0
    if len(pairs):
        d = np.abs(offsets[pairs[:, 0]] - offsets[pairs[:, 1]]) / OFFSET_UNIT
        gap = float(d.max())
    return UniquenessReport(
        arm=arm,
        max_condition_number=float((sv[:, 0] / sv[:, -1]).max()),
        min_singular_value=float(sv[:, -1].min()),
        worst_crb_std=crb,
        min_margin_px=float(margin),
        min_depth=float(depth),
        pairs_checked=len(pairs),
        max_offset_gap_of_close_pairs=gap,
        tol_px=tol_px,
        epsilon=epsilon,
    )


def expected_keypoints(arm: str, q_meas, camera, offset=None) -> np.ndarray:
    """Keypoint pixels (4×2) expected from measured joints (plus an offset estimate, 3 values)."""
    q = np.asarray(q_meas, dtype=float).copy()
    if offset is not None:
        q[:3] += np.asarray(offset, dtype=float)[:3]
    return project_keypoints(q, CALIBRATION_JAW, PSM_BASES[arm], camera)[0]


def keypoints_world(arm: str, q_actual, jaw: float = CALIBRATION_JAW) -> np.ndarray:
    """3-D keypoints (4×3, world) of ``arm`` at true joints ``q_actual``."""
    return keypoints_in_world(q_actual, jaw, PSM_BASES[arm])[0]
