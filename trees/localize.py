"""``localize``: localise the needle where it starts (in PSM2's jaw: presented; else free)."""

from __future__ import annotations

import operator

import py_trees
from py_trees.common import ComparisonExpression

from suture_bt.behaviours import blackboard_keys as keys
from suture_bt.behaviours.actions import Localize
from suture_bt.behaviours.needle_start import NeedleStart


def create_tree(policy: str = "stop") -> py_trees.behaviour.Behaviour:
    """Decide where the needle starts, then localise it there."""
    del policy
    choose = py_trees.idioms.either_or(
        conditions=[
            ComparisonExpression(keys.NEEDLE_START.name, "jaw", operator.eq),
            ComparisonExpression(keys.NEEDLE_START.name, "tissue", operator.eq),
        ],
        subtrees=[Localize("psm2"), Localize(None)],
        name="Where is the needle?",
    )
    return py_trees.composites.Sequence(
        "Localize the needle", memory=True, children=[NeedleStart("psm2"), choose]
    )


def main(argv: list[str] | None = None) -> int:
    """Run this tree through the front door (``suture-bt run localize ...``)."""
    import sys

    from suture_bt.cli import main as cli_main  # the front door wires a world to the tree

    return cli_main(["run", "localize", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
