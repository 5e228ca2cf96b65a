"""The options ``suture-bt run`` and ``suture-bt debug`` share: which tree, on which scene,
where the results and the recording go, the failure policy and the oracle ablation."""

from __future__ import annotations

from suture_bt.trees import TREE_NAMES


def add_session_arguments(p, verb: str, default_out: str, oracle_help: str) -> None:
    """Add TREE, --scene, --seed, --out, --rerun, --policy and --oracle to parser ``p``."""
    p.add_argument(
        "tree",
        nargs="?",
        default="multi_throw",
        metavar="TREE",
        help=f"tree to {verb}: {', '.join(TREE_NAMES)} (default multi_throw)",
    )
    p.add_argument(
        "--scene",
        metavar="FILE",
        help="scene YAML (default: the embedded SRC scene at the Task 3 start, "
        "needle in PSM2's jaw)",
    )
    p.add_argument("--seed", type=int, metavar="N", help="scene seed (random offsets, noise)")
    p.add_argument("--out", metavar="DIR", default=default_out, help="where results go")
    p.add_argument(
        "--rerun",
        choices=("save", "spawn", "off"),
        default="save",
        help="record the run to DIR/run.rrd (save, default), also stream it to a viewer "
        "(spawn), or not (off)",
    )
    p.add_argument(
        "--policy",
        choices=("stop", "continue"),
        default="stop",
        help="after a failed throw: end the run (stop) or go on (continue)",
    )
    p.add_argument("--oracle", action="store_true", help=oracle_help)
