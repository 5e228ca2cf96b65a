"""``suture-bt data TARGET --n N --out DIR [--seed S]``: render a training dataset.

Targets live in :data:`TARGETS` (name → generator ``fn(n, out, seed) -> meta dict``), each
registered by ``@target(name)`` on its function.
"""

from __future__ import annotations

import json
from pathlib import Path

from suture_bt.commands.targets import add_target_command, target_registry

#: Dataset generators by target name (``@target(name)`` registers one).
TARGETS, target = target_registry()


@target("needle")
def _needle(n: int, out: Path, seed: int) -> dict:
    from suture_bt.datagen.needle_data import generate

    return generate(n, out, seed)


@target("needle-varied")
def _needle_varied(n: int, out: Path, seed: int) -> dict:
    """Needle data with the phantom moved and the light tilted in a share of the scenes."""
    from suture_bt.datagen.needle_data import generate
    from suture_bt.datagen.scene_variety import VARIED_SCENES

    return generate(n, out, seed, variety=VARIED_SCENES)


@target("calibration")
def _calibration(n: int, out: Path, seed: int) -> dict:
    from suture_bt.datagen.calibration_data import generate

    return generate(n, out, seed)


def register(subparsers) -> None:
    summary = "render a simulated training dataset"
    p = add_target_command(subparsers, "data", summary, TARGETS, "which dataset", run)
    p.add_argument("--n", type=int, required=True, help="number of scenes")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")


def run(args) -> int:
    if args.n < 1:
        raise ValueError(f"--n must be ≥ 1, got {args.n}")
    meta = TARGETS[args.target](args.n, Path(args.out), args.seed)
    print(json.dumps(meta))
    return 0
