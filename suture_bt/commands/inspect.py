"""``suture-bt inspect run.rrd``: what a saved run did, as text, with no viewer.

Prints the run (tree, seed, scene, result), the tick range, every node with its transitions
and final status, each failure with its reason and tick, and the failed checks. ``--node``
prints one node's transitions; ``--tree-at TICK`` the tree as it was at that tick;
``--log`` the whole log; ``--entities`` each entity's rows and tick range.
"""

from __future__ import annotations

from pathlib import Path

#: The tree's text logs, in the order a node's entries and ``--log`` list them.
TREE_LOGS = ("bt/log", "bt/checks", "bt/refusals")


def register(subparsers) -> None:
    p = subparsers.add_parser("inspect", help="print what a saved run.rrd did (no viewer)")
    p.add_argument("rrd", metavar="RUN.rrd", help="a recording saved by run or debug")
    p.add_argument("--node", metavar="NAME", help="print this node's transitions")
    p.add_argument("--tree-at", type=int, metavar="TICK", help="print the tree at this tick")
    p.add_argument("--log", action="store_true", help="print the whole log (INFO and above)")
    p.add_argument("--entities", action="store_true", help="print every entity's tick range")
    p.set_defaults(func=run)


def _when(e) -> str:
    return f"tick {e.tick} ({e.sim_time:.2f} s)" if e.tick is not None else "static"


def _result_lines(result: dict | None) -> list[str]:
    if result is None:
        return ["result: none recorded (the run did not finish writing its result)"]
    verdict = "PASSED" if result.get("passed") else "FAILED"
    throws = result.get("throws", [])
    passed = sum(1 for t in throws if t.get("passed"))
    lines = [
        f"result: {verdict}, tree {result.get('tree_status')}, {passed}/{len(throws)} throws, "
        f"{result.get('sim_time_s')} s simulated, {result.get('ticks')} ticks"
    ]
    why = result.get("error") or result.get("tree_failure")
    if why:
        lines.append(f"  ended by: {why}")
    for t in throws:
        mark = "passed" if t.get("passed") else f"FAILED: {t.get('failure')}"
        lines.append(f"  pair {t.get('pair')}: {mark}")
    return lines


def _node_lines(rec) -> list[str]:
    lines = ["nodes (final status, transitions, ticks from first RUNNING to the last change):"]
    for node in rec.nodes:
        lane = rec.lanes.get(node["path"], [])
        depth = node["path"].count("/")
        label = "  " * depth + node["name"]
        if not lane:
            lines.append(f"  {label:58s} never ticked")
            continue
        running = [e.tick for e in lane if e.text == "RUNNING"]
        span = f"ticks {running[0]}..{lane[-1].tick}" if running else f"tick {lane[-1].tick}"
        fails = sum(1 for e in lane if e.text == "FAILURE")
        extra = f", {fails} failure(s)" if fails else ""
        lines.append(f"  {label:58s} {lane[-1].text:8s} {len(lane):3d} change(s), {span}{extra}")
    return lines


def run(args) -> int:
    from suture_bt.recording.reader import read_run

    rec = read_run(Path(args.rrd))
    info = rec.info
    print(f"recording: {rec.path}")
    if info:
        print(
            f"run: tree {info.get('tree')}, seed {info.get('seed')}, scene {info.get('scene')}, "
            f"{info.get('mode')}"
        )
    span = rec.tick_range
    if span is None:
        print("ticks: none recorded")
    else:
        times = [e.sim_time for v in rec.lanes.values() for e in v if e.sim_time is not None]
        t = f" (sim {min(times):.2f}..{max(times):.2f} s)" if times else ""
        print(f"ticks: {span[0]}..{span[1]}{t}; {len(rec.entities)} entities; "
              f"blueprint {'stored' if rec.blueprints else 'MISSING'}")  # fmt: skip
    for line in _result_lines(rec.result):
        print(line)
    if args.tree_at is not None:
        tree = rec.tree_at(args.tree_at)
        print(f"\ntree at tick {args.tree_at}" + (f" (logged {_when(tree)}):" if tree else ":"))
        print(tree.text if tree else "  (no tree logged at or before that tick)")
        return 0
    if args.node:
        key = args.node.lower()
        found = [n for n in rec.nodes if key in n["name"].lower() or key in n["path"].lower()]
        if not found:
            raise ValueError(f"no node named {args.node!r} in {rec.path}")
        for n in found:
            print(f"\n{n['name']}  [{n['class']}]  {n['path']}")
            for e in rec.lanes.get(n["path"], []):
                print(f"  {_when(e)} {e.text}")
            for e in (e for name in TREE_LOGS for e in rec.logs.get(name, [])):
                if e.node_path == n["path"]:
                    print(f"  {_when(e)} [{e.level}] {e.text}")
        return 0
    print()
    for line in _node_lines(rec):
        print(line)
    failures = rec.failures()
    print(f"\nfailures ({len(failures)}):")
    for e in failures:
        print(f"  {_when(e)} {e.text}  [{e.node_path}]")
    failed_checks = [e for e in rec.logs.get("bt/checks", []) if e.level == "WARN"]
    print(f"\nfailed checks ({len(failed_checks)}):")
    for e in failed_checks:
        print(f"  {_when(e)} {e.text}")
    refused = rec.logs.get("bt/refusals", [])
    print(f"\nrefused looks ({len(refused)}):")
    for e in refused:
        print(f"  {_when(e)} {e.text}")
    if args.log:
        print("\nlog:")
        for name in (*TREE_LOGS, "ground_truth/log"):
            for e in rec.logs.get(name, []):
                if e.level not in ("DEBUG", "TRACE"):
                    print(f"  {_when(e)} [{e.level}] {e.text}")
    if args.entities:
        print("\nentities (rows, ticks):")
        for name, st in sorted(rec.entities.items()):
            ticks = "static" if st.first_tick is None else f"{st.first_tick}..{st.last_tick}"
            print(f"  {name:60s} {st.rows:6d}  {ticks}")
    return 0
