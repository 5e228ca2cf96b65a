"""``single_throw``: prepare both arms, then one throw through one pair (default pair 1)."""

from __future__ import annotations

import py_trees

from suture_bt.behaviours.report import SutureReport
from suture_bt.trees.prepare import prepare
from suture_bt.trees.subtrees import in_reach
from suture_bt.trees.throw import throw


def create_tree(pair: int = 1, policy: str = "stop") -> py_trees.behaviour.Behaviour:
    """Calibration, the needle in PSM2's hand at the grasp ``pair`` needs, one throw."""
    del policy  # one throw: nothing to go on to
    return py_trees.composites.Sequence(
        f"Single throw (pair {pair})",
        memory=True,
        children=[in_reach((pair,)), prepare((pair,)), throw(pair, ()), SutureReport((pair,))],
    )


def main(argv: list[str] | None = None) -> int:
    """Run this tree through the front door (``suture-bt run single_throw ...``)."""
    import sys

    from suture_bt.cli import main as cli_main  # the front door wires a world to the tree

    return cli_main(["run", "single_throw", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
