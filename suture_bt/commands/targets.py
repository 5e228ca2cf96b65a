"""Subcommands of the form ``NAME TARGET``: TARGET chosen from a name → callable registry.

A command module builds its registry with :func:`target_registry` and decorates one function
per target; :func:`add_target_command` makes the subparser whose TARGET choices are the names.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable


def target_registry() -> tuple[dict[str, Callable], Callable[[str], Callable]]:
    """An empty registry and its decorator ``@target(name)`` that adds a function under name."""
    targets: dict[str, Callable] = {}

    def target(name: str) -> Callable[[Callable], Callable]:
        def add(fn: Callable) -> Callable:
            if name in targets:
                raise ValueError(f"target {name!r} is registered twice")
            targets[name] = fn
            return fn

        return add

    return targets, target


def add_target_command(
    subparsers, name: str, summary: str, targets: dict[str, Callable], what: str, run: Callable
) -> argparse.ArgumentParser:
    """The ``name`` subparser with a positional ``target`` (one of ``targets``) that calls
    ``run(args)``; returned so the caller adds its options."""
    p = subparsers.add_parser(name, help=summary)
    p.add_argument("target", choices=sorted(targets), help=what)
    p.set_defaults(func=run)
    return p
