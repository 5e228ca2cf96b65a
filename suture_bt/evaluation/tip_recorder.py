"""Needle-tip trajectory recorder: the true tip (world) at a fixed simulated rate, to CSV.

Front door (DESIGN.md §2): reads :class:`~suture_bt.sim.ground_truth.GroundTruth` through a
periodic callback of the world; it never changes the simulation.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from suture_bt.sim.ground_truth import GroundTruth

CSV_HEADER = ("t", "tip_x", "tip_y", "tip_z")


class TipRecorder:
    """Records (t, true needle tip x, y, z in the world, metres) every ``1 / rate_hz`` s."""

    def __init__(self, world: Any, rate_hz: float = 100.0) -> None:
        """Start recording now; ``1 / rate_hz`` must be a whole number of physics ticks."""
        if not np.isfinite(rate_hz) or rate_hz <= 0:
            raise ValueError(f"rate_hz must be a positive finite rate, got {rate_hz!r}")
        self._world = world
        self._truth = GroundTruth(world)
        self._rows: list[tuple[float, float, float, float]] = []
        self._handle: object | None = world.add_periodic(1.0 / rate_hz, self._sample)

    def _sample(self, t: float) -> None:
        """Periodic callback: one row. Callbacks run before the tick's motion, so the state
        seen belongs to the previous tick's end, and is stamped with that time."""
        x, y, z = (float(v) for v in self._truth.needle_tip())
        self._rows.append((round(t - self._world.dt, 9), x, y, z))

    @property
    def rows(self) -> list[tuple[float, float, float, float]]:
        """A copy of the rows recorded so far: (t s, tip x, y, z m)."""
        return list(self._rows)

    def as_array(self) -> np.ndarray:
        """The rows as an N×4 float array (t, x, y, z)."""
        return np.array(self._rows, dtype=float).reshape(-1, 4)

    def write_csv(self, path: str | Path) -> Path:
        """Write the rows with header ``t,tip_x,tip_y,tip_z`` (metres, 9 decimals: nm)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(CSV_HEADER)
            for t, x, y, z in self._rows:
                w.writerow((f"{t:.6f}", f"{x:.9f}", f"{y:.9f}", f"{z:.9f}"))
        return path

    def detach(self) -> None:
        """Stop recording (idempotent); the rows stay."""
        if self._handle is not None:
            self._world.remove_periodic(self._handle)
            self._handle = None
