"""``suture-bt data TARGET --n N --out DIR [--seed S]``: render a training dataset.

Targets live in :data:`TARGETS` (name → generator callable ``fn(n, out, seed) -> meta dict``);
adding one is a one-line edit.
"""

from __future__ import annotations

import json
from pathlib import Path


def _needle(n: int, out: Path, seed: int) -> dict:
    from suture_bt.datagen.needle_data import generate

    return generate(n, out, seed)


def _calibration(n: int, out: Path, seed: int) -> dict:
    from suture_bt.datagen.calibration_data import generate

    return generate(n, out, seed)


#: Dataset generators by target name.
TARGETS = {
    "needle": _needle,
    "calibration": _calibration,
}


def register(subparsers) -> None:
    p = subparsers.add_parser("data", help="render a simulated training dataset")
    p.add_argument("target", choices=sorted(TARGETS), help="which dataset")
    p.add_argument("--n", type=int, required=True, help="number of scenes")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=run)


def run(args) -> int:
    if args.n < 1:
        raise ValueError(f"--n must be ≥ 1, got {args.n}")
    meta = TARGETS[args.target](args.n, Path(args.out), args.seed)
    print(json.dumps(meta))
    return 0
