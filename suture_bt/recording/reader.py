"""Read a saved run back with rerun's own reader (``rerun.chunk.RrdReader``), no viewer.

:func:`read_run` collects what ``suture-bt inspect`` prints: the run's options and result,
the tick range, each node's transitions (its StateChange lane), the log with every FAILURE
and its reason, the skills' checks, and each entity's row count and tick range.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa


@dataclass(frozen=True)
class Entry:
    """One timed row: a status (lanes) or a log line (with its level and node path)."""

    tick: int
    sim_time: float
    text: str
    level: str = ""
    node_path: str = ""


@dataclass
class EntityStats:
    """Rows of one entity and the ticks they span (None: static only)."""

    rows: int = 0
    first_tick: int | None = None
    last_tick: int | None = None

    def add(self, ticks: list[int], rows: int) -> None:
        self.rows += rows
        if ticks:
            lo, hi = min(ticks), max(ticks)
            self.first_tick = lo if self.first_tick is None else min(self.first_tick, lo)
            self.last_tick = hi if self.last_tick is None else max(self.last_tick, hi)


@dataclass
class RunRecording:
    """Everything :func:`read_run` found in one .rrd."""

    path: Path
    info: dict = field(default_factory=dict)
    nodes: list[dict] = field(default_factory=list)
    result: dict | None = None
    lanes: dict[str, list[Entry]] = field(default_factory=dict)
    logs: dict[str, list[Entry]] = field(default_factory=dict)
    trees: list[Entry] = field(default_factory=list)
    entities: dict[str, EntityStats] = field(default_factory=dict)
    blueprints: int = 0

    @property
    def tick_range(self) -> tuple[int, int] | None:
        ticks = [e.first_tick for e in self.entities.values() if e.first_tick is not None]
        ends = [e.last_tick for e in self.entities.values() if e.last_tick is not None]
        return (min(ticks), max(ends)) if ticks else None

    def name_of(self, path: str) -> str:
        for n in self.nodes:
            if n["path"] == path:
                return n["name"]
        return path.rsplit("/", 1)[-1]

    def failures(self) -> list[Entry]:
        """Every logged FAILURE with a reason (or of a skill, or of the tree), in tick order."""
        return [e for e in self.logs.get("bt/log", []) if e.level == "ERROR"]

    def tree_at(self, tick: int) -> Entry | None:
        """The tree text as it was at ``tick`` (the last one logged at or before it)."""
        before = [t for t in self.trees if t.tick <= tick]
        return before[-1] if before else None


def _column(rb: pa.RecordBatch, name: str) -> list[Any]:
    if name not in rb.schema.names:
        return [None] * rb.num_rows
    col = rb.column(name)
    if pa.types.is_duration(col.type) or pa.types.is_timestamp(col.type):
        return [None if v is None else v / 1e9 for v in col.cast(pa.int64()).to_pylist()]
    values = col.to_pylist()
    return [v[0] if isinstance(v, list) and v else (None if isinstance(v, list) else v)
            for v in values]  # fmt: skip


def read_run(path: str | Path) -> RunRecording:
    """Read ``path``; raises ValueError (one line) when it is missing or not a recording."""
    from rerun.chunk import RrdReader

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    try:
        reader = RrdReader(str(path))
        store = reader.store()
        chunks = store.stream().to_chunks()
        blueprints = len(reader.blueprints())
    except Exception as exc:  # noqa: BLE001 - rerun's errors become one line
        text = " ".join(str(exc).split())[:200]
        raise ValueError(f"{path}: not a readable rerun recording ({text})") from None
    run = RunRecording(path, blueprints=blueprints)
    for chunk in chunks:
        entity = chunk.entity_path.lstrip("/")
        rb = chunk.to_record_batch()
        ticks = _column(rb, "tick")
        times = _column(rb, "sim_time")
        run.entities.setdefault(entity, EntityStats()).add(
            [t for t in ticks if t is not None], rb.num_rows
        )
        if entity == "run/info":
            run.info = json.loads(_column(rb, "TextDocument:text")[-1])
        elif entity == "run/nodes":
            run.nodes = json.loads(_column(rb, "TextDocument:text")[-1])
        elif entity == "run/result":
            run.result = json.loads(_column(rb, "TextDocument:text")[-1])
        elif entity == "bt/tree":
            for k, t, text in zip(ticks, times, _column(rb, "TextDocument:text"), strict=True):
                run.trees.append(Entry(k, t, text))
        elif entity.startswith("bt/nodes/"):
            lane = run.lanes.setdefault(entity[len("bt/nodes/") :], [])
            for k, t, state in zip(ticks, times, _column(rb, "StateChange:state"), strict=True):
                lane.append(Entry(k, t, state))
        elif "TextLog:text" in rb.schema.names:
            rows = zip(
                ticks,
                times,
                _column(rb, "TextLog:text"),
                _column(rb, "TextLog:level"),
                _column(rb, "node_path"),
                strict=True,
            )
            log = run.logs.setdefault(entity, [])
            log += [Entry(k, t, x, lv or "", p or "") for k, t, x, lv, p in rows]
    for entries in (*run.lanes.values(), *run.logs.values(), run.trees):
        entries.sort(key=lambda e: e.tick if e.tick is not None else -1)
    return run
