"""SRC scoring of a run from its recorded tip trajectory and port frames alone (DESIGN.md §5).

Independent of the world's bookkeeping (:mod:`suture_bt.evaluation.throw_scores` scores the
phantom's own crossing records) and of the skills' image-based checks: this module sees only
``trajectory.csv`` (t, true tip x/y/z in the world at 100 Hz) and the world frames of the eight
ports from ``result.json``, so a campaign can re-score, and cross-check, every trial offline.

Rules (§5): a port crossing is a sign change of the tip's z in the port frame (+ → − at an
entry, − → + at an exit), counted when it happens within ``CAPTURE_MM`` of the port (the port
planes are unbounded); its lateral distance is √(x² + y²) at the crossing, found by linear
interpolation between samples. Throw i passes when an entry of Entry_i is followed by an exit of
Exit_i, both with lateral ≤ 2.5 mm, and the tip then gets ≥ 5 mm out past the exit (largest
distance from the exit crossing point while the tip stays outside). The first exit that follows
an entry is scored, with the last entry before it (a backed-out retry is scored by its redo).
Task 3 passes when the SRC-direction crossings, repeats at one port collapsed, are exactly
Entry1, Exit1, …, Entry4, Exit4. Stabs and strain are not trajectory quantities; the world's
figures for them are reported beside these scores.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: SRC thresholds (millimetres): lateral distance at a crossing, tip out past the exit.
LATERAL_MAX_MM = 2.5
TIP_OUT_MIN_MM = 5.0
#: A port-plane sign change farther than this from the port is not a crossing of that port.
CAPTURE_MM = 10.0


@dataclass(frozen=True)
class PortCrossing:
    """One sign change of the tip's z in a port frame (millimetres, seconds)."""

    port: str  # "Entry1" ... "Exit4"
    t: float
    into_tissue: bool  # z went + → − (the SRC direction at entries)
    lateral_mm: float
    point_mm: tuple[float, float, float]  # crossing point in the port frame
    tip_out_mm: float  # largest tip distance from the point while it stayed on the + side

    @property
    def scored_direction(self) -> bool:
        """True for + → − at an entry and − → + at an exit."""
        return self.into_tissue == self.port.startswith("Entry")


@dataclass
class ThrowVerdict:
    """One throw scored from the trajectory (None: that crossing never happened)."""

    pair: int
    passed: bool
    entry_lateral_mm: float | None
    exit_lateral_mm: float | None
    tip_out_mm: float | None
    entry_t: float | None
    exit_t: float | None
    failure: str | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (floats rounded to 4 decimals)."""
        out = dict(self.__dict__)
        for k, v in out.items():
            if isinstance(v, float):
                out[k] = round(v, 4)
        return out


@dataclass
class TrajectoryScore:
    """All crossings of a run, a verdict per throw, and the Task 3 order check."""

    crossings: list[PortCrossing]
    throws: list[ThrowVerdict]
    order_ok: bool
    sequence: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """Every throw passed and the crossings came in the Task 3 order."""
        return bool(self.throws) and all(t.passed for t in self.throws) and self.order_ok

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (crossings listed with their times)."""
        return {
            "passed": self.passed,
            "order_ok": self.order_ok,
            "sequence": list(self.sequence),
            "throws": [t.to_dict() for t in self.throws],
            "crossings": [
                {
                    "port": c.port,
                    "t": round(c.t, 4),
                    "scored_direction": c.scored_direction,
                    "lateral_mm": round(c.lateral_mm, 4),
                    "tip_out_mm": round(c.tip_out_mm, 4),
                }
                for c in self.crossings
            ],
        }


def load_trajectory(path: str | Path) -> np.ndarray:
    """``trajectory.csv`` as an N×4 array (t s, x, y, z m); checks the header."""
    with Path(path).open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows or [h.strip() for h in rows[0]] != ["t", "tip_x", "tip_y", "tip_z"]:
        raise ValueError(f"{path}: not a tip trajectory (header t,tip_x,tip_y,tip_z)")
    return np.array([[float(v) for v in r] for r in rows[1:] if r], dtype=float).reshape(-1, 4)


def _to_port(samples: np.ndarray, frame: Mapping[str, Any]) -> np.ndarray:
    """World tip samples (N×3, m) in a port frame {"p": origin, "R": axes as columns}, in mm."""
    R = np.asarray(frame["R"], dtype=float)
    p = np.asarray(frame["p"], dtype=float)
    return 1e3 * (samples - p) @ R


def port_crossings(trajectory: np.ndarray, ports: Mapping[str, Mapping[str, Any]]):
    """Every crossing of every port by the tip, in time order."""
    t, xyz = trajectory[:, 0], trajectory[:, 1:4]
    found: list[PortCrossing] = []
    for name, frame in ports.items():
        local = _to_port(xyz, frame)
        above = local[:, 2] > 0.0
        for k in np.flatnonzero(above[:-1] != above[1:]):
            a, b = local[k], local[k + 1]
            s = a[2] / (a[2] - b[2])
            point = a + s * (b - a)
            lateral = float(np.hypot(point[0], point[1]))
            if lateral > CAPTURE_MM:
                continue
            found.append(
                PortCrossing(
                    port=name,
                    t=float(t[k] + s * (t[k + 1] - t[k])),
                    into_tissue=bool(above[k]),
                    lateral_mm=lateral,
                    point_mm=(float(point[0]), float(point[1]), float(point[2])),
                    tip_out_mm=_tip_out(local, above, k + 1, point),
                )
            )
    return sorted(found, key=lambda c: c.t)


def _tip_out(local: np.ndarray, above: np.ndarray, start: int, point: np.ndarray) -> float:
    """Largest distance (mm) of the tip from ``point`` over the run of + side samples from
    ``start`` (0 when the tip went to the − side)."""
    if not above[start]:
        return 0.0
    below = np.flatnonzero(~above[start:])
    stop = start + (int(below[0]) if len(below) else len(above) - start)
    return float(np.max(np.linalg.norm(local[start:stop] - point, axis=1)))


def score_throw(pair: int, crossings: Iterable[PortCrossing]) -> ThrowVerdict:
    """Throw ``pair`` by the SRC rules (see the module docstring)."""
    mine = [
        c for c in crossings if c.scored_direction and c.port in (f"Entry{pair}", f"Exit{pair}")
    ]
    entry = exit_ = None
    for c in mine:
        if c.port.startswith("Entry"):
            entry = c
        elif entry is not None:
            exit_ = c
            break
    problems = []
    if entry is None:
        problems.append(f"no entry crossing of Entry{pair}")
    elif exit_ is None:
        problems.append(f"no exit crossing of Exit{pair} after the entry")
    for label, c in (("entry", entry), ("exit", exit_)):
        if c is not None and c.lateral_mm > LATERAL_MAX_MM:
            problems.append(f"{label} lateral {c.lateral_mm:.2f} mm > {LATERAL_MAX_MM} mm")
    if exit_ is not None and exit_.tip_out_mm < TIP_OUT_MIN_MM:
        problems.append(f"tip out {exit_.tip_out_mm:.2f} mm < {TIP_OUT_MIN_MM} mm")
    return ThrowVerdict(
        pair=pair,
        passed=not problems,
        entry_lateral_mm=None if entry is None else entry.lateral_mm,
        exit_lateral_mm=None if exit_ is None else exit_.lateral_mm,
        tip_out_mm=None if exit_ is None else exit_.tip_out_mm,
        entry_t=None if entry is None else entry.t,
        exit_t=None if exit_ is None else exit_.t,
        failure="; ".join(problems) or None,
    )


def crossing_sequence(crossings: Iterable[PortCrossing]) -> list[str]:
    """Ports of the scored-direction crossings in time order, repeats at one port collapsed."""
    seq: list[str] = []
    for c in crossings:
        if c.scored_direction and (not seq or seq[-1] != c.port):
            seq.append(c.port)
    return seq


def score_trajectory(
    trajectory: np.ndarray,
    ports: Mapping[str, Mapping[str, Any]],
    pairs: Iterable[int] = (1, 2, 3, 4),
) -> TrajectoryScore:
    """Score a run (N×4 trajectory, port frames as in ``result.json``) for ``pairs``."""
    trajectory = np.asarray(trajectory, dtype=float).reshape(-1, 4)
    pairs = tuple(pairs)
    crossings = port_crossings(trajectory, ports) if len(trajectory) > 1 else []
    seq = crossing_sequence(crossings)
    expected = [f"{kind}{i}" for i in pairs for kind in ("Entry", "Exit")]
    return TrajectoryScore(
        crossings=crossings,
        throws=[score_throw(i, crossings) for i in pairs],
        order_ok=seq == expected,
        sequence=seq,
    )


def score_run_dir(run_dir: str | Path) -> TrajectoryScore:
    """Score the ``trajectory.csv`` of a run directory with the ports and throws of its
    ``result.json``."""
    import json

    run_dir = Path(run_dir)
    result = json.loads((run_dir / "result.json").read_text())
    pairs = [int(t["pair"]) for t in result.get("throws", [])] or [1, 2, 3, 4]
    return score_trajectory(load_trajectory(run_dir / "trajectory.csv"), result["ports"], pairs)
