"""``suture-bt train TARGET [--data DIR ...] [--out PATH]``: train a network from dataset folders.

Targets live in :data:`TARGETS` (name → ``fn(args) -> result dict``), each registered by
``@target(name)`` on its function.
"""

from __future__ import annotations

import json
from pathlib import Path

from suture_bt.commands.targets import add_target_command, target_registry

#: Trainers by target name (``@target(name)`` registers one).
TARGETS, target = target_registry()

DEFAULT_DATA = {"needle": "data/needle", "calibration": "data/calibration"}


@target("needle")
def _needle(args) -> dict:
    from suture_bt.perception.network import DEFAULT_WEIGHTS
    from suture_bt.perception.training import TrainConfig, train

    cfg = TrainConfig(seed=args.seed)
    if args.steps is not None:
        cfg.steps = args.steps
    if args.minutes is not None:
        cfg.minutes = args.minutes
    cfg.threads = args.threads
    out = Path(args.out) if args.out else DEFAULT_WEIGHTS
    folders = [Path(f) for f in (args.data or [DEFAULT_DATA["needle"]])]
    return train(folders, out, cfg) | {"weights": str(out)}


@target("calibration")
def _calibration(args) -> dict:
    from suture_bt.calibration.training import train_calibration

    if args.data and len(args.data) > 1:
        raise SystemExit("suture-bt train calibration: give one --data folder")
    data = args.data[0] if args.data else DEFAULT_DATA["calibration"]
    return train_calibration(data, args.out, seed=args.seed, steps=args.steps, minutes=args.minutes)


def register(subparsers) -> None:
    summary = "train a network on a simulated dataset"
    p = add_target_command(subparsers, "train", summary, TARGETS, "which network", run)
    p.add_argument(
        "--data",
        metavar="DIR",
        nargs="+",
        help="dataset folder(s), joined (default: data/<target>; calibration takes one)",
    )
    p.add_argument("--out", metavar="PATH", help="weights file (default: the packaged weights)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--steps", type=int, help="maximum number of updates")
    p.add_argument("--minutes", type=float, help="wall-time cap in minutes")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")


def run(args) -> int:
    result = TARGETS[args.target](args)
    print(json.dumps(result))
    return 0
