"""``suture-bt run [TREE]``: the main job — a suture tree in the simulated SRC scene, headless.

Prints a live progress line (throw, current behaviour, simulated time), then a table per
throw scored from the world's records, and writes ``result.json``, ``trajectory.csv`` and the
rerun recording ``run.rrd`` (``--rerun``) to ``--out`` (also when the run fails). Exit status
0 only when every throw passed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from suture_bt.commands.session_args import add_session_arguments
from suture_bt.trees import TREE_NAMES


def register(subparsers) -> None:
    p = subparsers.add_parser("run", help="run a suture tree headless (default: the full suture)")
    add_session_arguments(
        p, "run", "out/run", "ABLATION: feed ground truth (needle pose, offsets) to the skills"
    )
    p.set_defaults(func=run)


class Progress:
    """One live line on a terminal; a line per change of behaviour otherwise."""

    def __init__(self, stream=sys.stdout):
        self.stream = stream
        self.tty = stream.isatty()
        self.last = ""

    def __call__(self, session) -> None:
        pair = session.context.throws and max(session.context.throws)
        where = f"throw {pair}" if pair else "prepare"
        node = session.root.tip()
        name = node.name if node is not None else ""
        t = session.context.clock.now()
        if self.tty:
            line = f"\r[{t:6.1f} s] {where} | {session.current()}"[:150]
            self.stream.write(line.ljust(150))
            self.stream.flush()
        elif name != self.last:
            self.stream.write(f"[{t:6.1f} s] {where} | {name}\n")
            self.stream.flush()
        self.last = name

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def run(args) -> int:
    # Imported here: building the parser must not load pybullet, torch or the networks.
    from suture_bt.runtime.recording import attach_recording
    from suture_bt.runtime.results import throw_table
    from suture_bt.runtime.session import RunOptions, Session

    if args.tree not in TREE_NAMES:
        raise ValueError(f"unknown tree {args.tree!r}; choose one of: {', '.join(TREE_NAMES)}")
    options = RunOptions(
        tree=args.tree, scene=args.scene, seed=args.seed, oracle=args.oracle, policy=args.policy
    )
    out = Path(args.out)
    session = Session(options)
    try:
        label = " [ORACLE]" if args.oracle else ""
        print(
            f"suture-bt run {args.tree}{label}: scene "
            f"{args.scene or 'SRC Task 3 start'}, seed {session.scene.seed}"
        )
        rrd = attach_recording(session, args.rerun, out / "run.rrd")
        progress = Progress()
        try:
            session.run(progress)
        except KeyboardInterrupt:
            session.error = "interrupted"
        progress.close()
        result = session.write(out)
    finally:
        session.close()
    print(throw_table(result))
    files = [out / "result.json", out / "trajectory.csv"] + ([rrd] if rrd else [])
    print("results: " + ", ".join(str(f) for f in files))
    for warning in session.observer.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    return 0 if result["passed"] else 1
