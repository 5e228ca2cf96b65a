"""The oracle ablation: ground truth fed to the skills, for measuring what perception costs.

Never the default; every output of an oracle run says so (``oracle: true``).
"""

from __future__ import annotations

import numpy as np

from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.skills.context import NeedleObservation


class OracleNeedleSensor:
    """Answers every look with the true needle pose (labelled ``oracle``)."""

    def __init__(self, world, clock):
        self._truth = GroundTruth(world)
        self._clock = clock
        self.calls = 0

    def observe(
        self,
        previous: np.ndarray | None = None,
        prior_checked: bool = False,
        holder: tuple[str, np.ndarray] | None = None,
        holder_tolerance: float = 0.004,
        jaw_tolerance_deg: float | None = None,
        held_face: np.ndarray | None = None,
    ) -> NeedleObservation:
        self.calls += 1
        return NeedleObservation(self._truth.needle_pose(), self._clock.now(), 0.0, 0.0, "oracle")

    def support(self, T_world_needle: np.ndarray, angles: np.ndarray) -> tuple[float, float]:
        """Share of the predicted arc samples within 0.5 mm of the true needle's."""
        hits, _ = self.hits(T_world_needle, angles)
        share = float(hits.mean()) if len(hits) else 0.0
        return share, share

    def seen_pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """No image evidence: the oracle answers from the truth, never refuses."""
        return np.zeros((0, 2)), np.zeros((0, 2))

    def hits(self, T_world_needle: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per predicted arc sample: within 0.5 mm of the true needle's centre-line."""
        from suture_bt.geometry import NeedleModel

        needle = NeedleModel()
        pts = needle.point_at(np.asarray(angles, dtype=float))
        T = self._truth.needle_pose()
        pred = pts @ np.asarray(T_world_needle)[:3, :3].T + np.asarray(T_world_needle)[:3, 3]
        line = needle.point_at(np.linspace(needle.tip_angle, needle.base_angle, 400))
        true = line @ T[:3, :3].T + T[:3, 3]
        d = np.min(np.linalg.norm(pred[:, None] - true[None], axis=2), axis=1)
        hits = d < 5e-4
        return hits, hits.copy()


def offset_oracle(world):
    """``arm -> true Δq`` (joints 1-3) for the calibration skill's oracle mode."""
    truth = GroundTruth(world)
    return lambda arm: truth.joint_offset(arm)[:3]
