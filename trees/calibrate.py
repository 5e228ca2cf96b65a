"""``calibrate``: calibrate both arms (handing the needle over when PSM2 holds it)."""

from __future__ import annotations

import py_trees

from suture_bt.trees.multi_throw import PAIRS
from suture_bt.trees.prepare import prepare


def create_tree(policy: str = "stop") -> py_trees.behaviour.Behaviour:
    """Both arms calibrated; the needle ends in PSM2's jaw at the throws' grasp."""
    del policy
    return py_trees.composites.Sequence(
        "Calibrate both arms", memory=True, children=[prepare(PAIRS)]
    )


def main(argv: list[str] | None = None) -> int:
    """Run this tree through the front door (``suture-bt run calibrate ...``)."""
    import sys

    from suture_bt.cli import main as cli_main  # the front door wires a world to the tree

    return cli_main(["run", "calibrate", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
