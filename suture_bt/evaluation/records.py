"""The ground-truth records that scoring needs, collected from a world after (or during) a run.

Front door (DESIGN.md §2): reads :class:`~suture_bt.sim.ground_truth.GroundTruth` only; the
scoring in :mod:`suture_bt.evaluation.throw_scores` then works on these plain records.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from suture_bt.evaluation.throw_scores import ThrowScore, Window, score_throws

if TYPE_CHECKING:
    from suture_bt.sim.ground_truth import GroundTruth


@dataclass
class EvaluationRecords:
    """Port crossings, tissue entries, peak strain per port and port positions (world)."""

    crossings: list[Any]
    tissue_entries: list[Any]
    max_strain: dict[str, Any]
    port_positions: dict[str, np.ndarray] = field(default_factory=dict)

    def score(
        self, windows: dict[int, Window], pairs: tuple[int, ...] = (1, 2, 3, 4)
    ) -> list[ThrowScore]:
        """:func:`~suture_bt.evaluation.throw_scores.score_throws` on these records."""
        return score_throws(
            self.crossings,
            self.tissue_entries,
            self.max_strain,
            windows,
            pairs,
            port_positions=self.port_positions or None,
        )


def records_from_world(truth: GroundTruth) -> EvaluationRecords:
    """Snapshot of a world's scoring records (copies of the lists; the records themselves are
    the phantom's, so an open exit's ``tip_out`` is final only once the run is over)."""
    phantom = truth.phantom_state()
    return EvaluationRecords(
        crossings=truth.port_crossings(),
        tissue_entries=truth.tissue_entries(),
        max_strain=dict(phantom.max_strain),
        port_positions={q.name: np.array(q.position) for q in phantom.phantom.ports()},
    )
