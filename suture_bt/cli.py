"""The ``suture-bt`` console script: one subcommand per module in ``suture_bt.commands``.

Every failure the user can cause (missing or malformed file, bad arguments) ends with one line
on stderr and a non-zero exit status, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from suture_bt.sim.quiet import import_pybullet_quietly  # noqa: E402

import_pybullet_quietly()  # before the commands import the simulator

from suture_bt.commands import data as data_command  # noqa: E402
from suture_bt.commands import debug as debug_command  # noqa: E402
from suture_bt.commands import eval as eval_command  # noqa: E402
from suture_bt.commands import inspect as inspect_command  # noqa: E402
from suture_bt.commands import replay as replay_command  # noqa: E402
from suture_bt.commands import run as run_command  # noqa: E402
from suture_bt.commands import scene as scene_command  # noqa: E402
from suture_bt.commands import train as train_command  # noqa: E402

#: Subcommand modules; each has ``register(subparsers)`` that sets ``func`` on its parser.
COMMANDS = [
    scene_command,
    run_command,
    debug_command,
    replay_command,
    inspect_command,
    data_command,
    train_command,
    eval_command,
]

PROG = "suture-bt"


class UsageError(Exception):
    """Bad command-line arguments (exit status 2)."""


class _Parser(argparse.ArgumentParser):
    """An argparse parser that reports errors as one line instead of usage + message + exit."""

    def error(self, message: str):  # noqa: D102 - argparse API
        raise UsageError(f"{message} (see '{PROG} --help')")


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with all registered subcommands."""
    parser = _Parser(prog=PROG, description="Autonomous suturing with two dVRK PSMs in pybullet.")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for module in COMMANDS:
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if getattr(args, "func", None) is None:
            raise UsageError(f"a command is required (see '{PROG} --help')")
        return int(args.func(args) or 0)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the front door never shows a traceback
        text = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{PROG}: error: {text}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
