"""``suture-bt debug [TREE]``: step a suture tree tick by tick, with breakpoints.

Interactive at a terminal (``help`` lists the commands); scripted with ``--commands FILE``
(``-`` for stdin) or when stdin is not a terminal. The run is the same as ``suture-bt run``'s
with the same seed, paused or not; its ``result.json``, ``trajectory.csv`` and ``run.rrd`` go
to ``--out``. Exit status as for ``run``: 0 only when every throw passed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from suture_bt.commands.session_args import add_session_arguments
from suture_bt.trees import TREE_NAMES


def register(subparsers) -> None:
    p = subparsers.add_parser("debug", help="step a tree tick by tick (breakpoints, tree, bb)")
    add_session_arguments(
        p,
        "debug",
        "out/debug",
        "ABLATION: feed ground truth to the skills ('world' then shows the true needle)",
    )
    p.add_argument(
        "--commands",
        metavar="FILE",
        help="run the debugger commands in FILE ('-': stdin) instead of prompting",
    )
    p.set_defaults(func=run)


def _read_commands(source: str) -> list[str]:
    if source == "-":
        return sys.stdin.read().splitlines()
    path = Path(source)
    if not path.is_file():
        raise ValueError(f"commands file {source}: no such file")
    try:
        return path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"commands file {source}: cannot be read ({exc})") from None


def run(args) -> int:
    # Imported here: building the parser must not load pybullet, torch or the networks.
    from suture_bt.runtime.debugger import CommandError, Debugger, parse_script
    from suture_bt.runtime.recording import attach_recording
    from suture_bt.runtime.results import throw_table
    from suture_bt.runtime.session import RunOptions, Session

    if args.tree not in TREE_NAMES:
        raise ValueError(f"unknown tree {args.tree!r}; choose one of: {', '.join(TREE_NAMES)}")
    script = None
    scripted = args.commands is not None or not sys.stdin.isatty()
    if scripted:
        source = args.commands or "-"
        name = "stdin" if source == "-" else source
        try:
            script = parse_script(_read_commands(source), f"commands file {name}")
        except CommandError as exc:
            raise ValueError(str(exc)) from None
    options = RunOptions(
        tree=args.tree, scene=args.scene, seed=args.seed, oracle=args.oracle, policy=args.policy
    )
    out = Path(args.out)
    session = Session(options)
    result = None
    try:
        label = " [ORACLE]" if args.oracle else ""
        print(
            f"suture-bt debug {args.tree}{label}: scene "
            f"{args.scene or 'SRC Task 3 start'}, seed {session.scene.seed}"
        )
        rrd = attach_recording(session, args.rerun, out / "run.rrd")
        truth = None
        if args.oracle:
            from suture_bt.sim.ground_truth import GroundTruth

            truth = GroundTruth(session.world)

        def on_end() -> None:
            nonlocal result
            result = session.write(out)
            print(throw_table(result))
            files = [out / "result.json", out / "trajectory.csv"] + ([rrd] if rrd else [])
            print("results: " + ", ".join(str(f) for f in files))

        debugger = Debugger(session, on_end=on_end, truth=truth)
        if script is not None:
            try:
                debugger.check(script, f"commands file {args.commands or 'stdin'}")
            except CommandError as exc:
                raise ValueError(str(exc)) from None
            debugger.run_script(script)
        else:
            debugger.interactive()
    finally:
        session.close()
    for warning in session.observer.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    return 0 if result is not None and result["passed"] else 1
