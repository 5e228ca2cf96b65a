"""``suture-bt eval``: a randomized evaluation campaign scored by the SRC rules (issue 18).

N seeded trials, each a full run whose scene is drawn from the trial's seed, on a local
process pool (default) or a Ray cluster; resumable (finished trials are skipped) and
crash-isolated (a trial that raises, dies or runs out of time is an error with its reason).
Writes ``results.json``, ``summary.md`` and PNG plots into ``--out``.
"""

from __future__ import annotations


def register(subparsers) -> None:
    """Add the ``eval`` subcommand."""
    p = subparsers.add_parser("eval", help="randomized evaluation campaign (SRC scoring, report)")
    p.add_argument("--trials", type=int, required=True, metavar="N", help="number of trials")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run the campaign; exit status 0 when every trial ran (passed or failed), 1 on errors."""
    raise ValueError("suture-bt eval is not implemented yet")
