"""What the rerun recording costs: the same run with ``--rerun off`` and ``--rerun save``.

    .venv/bin/python benchmarks/recording.py [--tree single_throw] [--seed 0] [--repeats 2]
                                             [--json recording.json]

Runs alternate (off, save, off, save, ...) in one process so that both see the same machine
load. Reported per mode: the run's wall time (building the world to closing the recording,
flush included), its ticks' wall time, and for ``save`` the time spent inside the recording
sink's hooks and the .rrd size, and the process CPU time (all threads, rerun's writer threads
included: less sensitive to other load on a shared machine than wall time). Overhead =
median(save) / median(off) - 1, for wall and CPU time; the issue asks for at most 25 %. Both
modes must give the same result.json (except wall time).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from suture_bt.recording.scene_sink import SceneSink
from suture_bt.recording.tree_sink import TreeSink
from suture_bt.runtime.recording import attach_recording
from suture_bt.runtime.session import RunOptions, Session

LIMIT = 0.25


class _Timed:
    """Wraps a sink's hooks to add up the wall time spent in them (shared by all wrapped)."""

    seconds = 0.0

    def __init__(self, sink: Any):
        self.sink = sink

    def __getattr__(self, name: str) -> Any:
        hook = getattr(self.sink, name)

        def timed(*args: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return hook(*args)
            finally:
                _Timed.seconds += time.perf_counter() - t0

        return timed


def one_run(tree: str, seed: int, mode: str, out: Path) -> dict[str, Any]:
    """One run; wall times, the sink's own time, the .rrd size and the result."""
    t0, c0 = time.perf_counter(), time.process_time()
    session = Session(RunOptions(tree=tree, seed=seed))
    _Timed.seconds = 0.0
    try:
        path = attach_recording(session, mode, out / "run.rrd", say=lambda _: None)
        sinks = session.observer.sinks
        for k, sink in enumerate(sinks):
            if isinstance(sink, TreeSink | SceneSink):
                sinks[k] = _Timed(sink)  # type: ignore[assignment]
        session.run()
        result = session.write(out)
    finally:
        session.close()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    row = {
        "mode": mode,
        "wall_s": wall,
        "cpu_s": cpu,
        "tick_wall_s": session.wall_time,
        "ticks": session.ticks,
        "sink_s": _Timed.seconds,
        "rrd_mb": (out / "run.rrd").stat().st_size / 1e6 if path else 0.0,
        "warnings": session.observer.warnings,
    }
    result.pop("wall_time_s", None)
    return row | {"result": result}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", default="single_throw")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for mode in ("off", "save"):
                row = one_run(args.tree, args.seed, mode, Path(tmp) / f"{mode}{r}")
                rows.append(row)
                print(
                    f"  {mode:4s} run {r + 1}: {row['wall_s']:6.1f} s wall,"
                    f" {row['cpu_s']:6.1f} s CPU, {row['ticks']} ticks,"
                    f" sink {row['sink_s']:5.2f} s, rrd {row['rrd_mb']:.1f} MB",
                    file=sys.stderr,
                )
    by = {m: [r for r in rows if r["mode"] == m] for m in ("off", "save")}
    med = {m: statistics.median(r["wall_s"] for r in by[m]) for m in by}
    ticks = {m: statistics.median(r["tick_wall_s"] for r in by[m]) for m in by}
    cpu = {m: statistics.median(r["cpu_s"] for r in by[m]) for m in by}
    sink = statistics.median(r["sink_s"] for r in by["save"])
    overhead = med["save"] / med["off"] - 1.0
    cpu_overhead = cpu["save"] / cpu["off"] - 1.0
    same = all(r["result"] == rows[0]["result"] for r in rows)
    print(f"recording overhead, tree {args.tree}, seed {args.seed}, {args.repeats} run(s) each")
    head = ("wall s (median)", "CPU s", "ticks wall s", "sink s", "rrd MB")
    print(f"{'mode':6s} {head[0]:>16s} {head[1]:>8s} {head[2]:>13s} {head[3]:>8s} {head[4]:>7s}")
    for m in ("off", "save"):
        rrd = statistics.median(r["rrd_mb"] for r in by[m])
        s = sink if m == "save" else 0.0
        print(f"{m:6s} {med[m]:16.1f} {cpu[m]:8.1f} {ticks[m]:13.1f} {s:8.2f} {rrd:7.1f}")
    in_sinks = 100 * sink / med["off"]
    print(
        f"overhead {100 * overhead:+.1f} % of wall time, {100 * cpu_overhead:+.1f} % of CPU "
        f"time (all threads; limit {100 * LIMIT:.0f} %); time in the sinks {in_sinks:.1f} % "
        f"of the unrecorded wall time; same result: {same}"
    )
    if args.json:
        doc = {
            "tree": args.tree,
            "seed": args.seed,
            "repeats": args.repeats,
            "overhead": overhead,
            "cpu_overhead": cpu_overhead,
            "sink_fraction": sink / med["off"],
            "limit": LIMIT,
            "same_result": same,
            "median_wall_s": med,
            "median_cpu_s": cpu,
            "runs": [{k: v for k, v in r.items() if k != "result"} for r in rows],
            "machine": {"python": platform.python_version(), "cpu": platform.processor()},
        }
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    return 0 if max(overhead, cpu_overhead) <= LIMIT and same else 1


if __name__ == "__main__":
    raise SystemExit(main())
