"""``multi_throw``: SRC Task 3 — calibrate both arms, then four throws in order, then a report.

Run it: ``python -m suture_bt.trees.multi_throw`` (the full suture on the Task 3 start scene),
or ``--render`` to print the tree.
"""

from __future__ import annotations

import py_trees

from suture_bt.behaviours.report import SutureReport
from suture_bt.trees.prepare import prepare
from suture_bt.trees.subtrees import in_reach
from suture_bt.trees.throw import throw

PAIRS = (1, 2, 3, 4)


def create_tree(
    pairs: tuple[int, ...] = PAIRS, policy: str = "stop"
) -> py_trees.behaviour.Behaviour:
    """The full suture; ``policy`` "stop" ends the run at a failed throw, "continue" goes on."""
    if policy not in ("stop", "continue"):
        raise ValueError(f"policy must be 'stop' or 'continue', got {policy!r}")
    pairs = tuple(pairs)
    throws = []
    for i, pair in enumerate(pairs):
        node = throw(pair, pairs[i + 1 :])
        if policy == "continue":
            node = py_trees.decorators.FailureIsSuccess(f"Go on after throw {pair}", node)
        throws.append(node)
    # Stopping at the first failed throw: a pair out of reach ends the run before anything
    # moves. Going on: each throw checks its own pair.
    first = [in_reach(pairs)] if policy == "stop" else []
    return py_trees.composites.Sequence(
        "Suture (SRC Task 3)",
        memory=True,
        children=[*first, prepare(pairs), *throws, SutureReport(pairs)],
    )


def main(argv: list[str] | None = None) -> int:
    """Run this tree through the front door (``suture-bt run multi_throw ...``)."""
    import sys

    from suture_bt.cli import main as cli_main  # the front door wires a world to the tree

    return cli_main(["run", "multi_throw", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
