"""Tree factories: ``create_tree(...)`` for the full suture, one throw, calibration, localisation.

``create(name, **options)`` builds a tree by name (an unknown name is a clear ValueError).
"""

from __future__ import annotations

from collections.abc import Callable

import py_trees


def _factories() -> dict[str, Callable[..., py_trees.behaviour.Behaviour]]:
    from suture_bt.trees import calibrate, localize, multi_throw, single_throw

    return {
        "multi_throw": multi_throw.create_tree,
        "single_throw": single_throw.create_tree,
        "calibrate": calibrate.create_tree,
        "localize": localize.create_tree,
    }


TREE_NAMES = ("multi_throw", "single_throw", "calibrate", "localize")


def create(name: str, **options) -> py_trees.behaviour.Behaviour:
    """The tree ``name`` built with ``options`` (e.g. ``policy``)."""
    factories = _factories()
    if name not in factories:
        raise ValueError(f"unknown tree {name!r}; choose one of: {', '.join(TREE_NAMES)}")
    return factories[name](**options)
