"""Evaluation (front door): SRC throw scores from ground truth after a run, tip trajectories.

Scoring needs no simulator: importing this package does not import pybullet; ``TipRecorder``
(which reads a live world) is loaded on first use.
"""

from __future__ import annotations

from typing import Any

from suture_bt.evaluation.records import EvaluationRecords, records_from_world
from suture_bt.evaluation.throw_scores import (
    ThrowScore,
    run_passed,
    score_throw,
    score_throws,
    src_sequence,
    task3_order_ok,
)

__all__ = [
    "EvaluationRecords",
    "ThrowScore",
    "TipRecorder",
    "records_from_world",
    "run_passed",
    "score_throw",
    "score_throws",
    "src_sequence",
    "task3_order_ok",
]


def __getattr__(name: str) -> Any:
    """Lazy ``TipRecorder`` (it imports the simulator's ground truth)."""
    if name == "TipRecorder":
        from suture_bt.evaluation.tip_recorder import TipRecorder

        return TipRecorder
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
