"""What simulator objects can be reached from an object by plain attribute access (DESIGN.md §3).

``reachable_sim_objects(root)`` walks an object graph the way skill code could without
introspection tricks: instance ``vars()``, ``__slots__`` (private names mangled), dataclass
fields and the items of dicts, lists, tuples and sets. It does not call properties or
methods and does not look inside functions, modules, classes, numpy arrays or primitives
(closures are what the views hide the simulator in; the source checks in
``test_honesty_boundary.py`` forbid the introspection that would open them).
"""

from __future__ import annotations

import dataclasses
import types
from collections import deque
from collections.abc import Iterator, Mapping

import numpy as np

SIM_PREFIX = "suture_bt.sim"

_OPAQUE = (
    types.ModuleType,
    types.FunctionType,
    types.BuiltinFunctionType,
    types.MethodType,
    types.MethodWrapperType,
    types.WrapperDescriptorType,
    types.MethodDescriptorType,
    types.GeneratorType,
    types.CodeType,
    type,
    np.ndarray,
    np.generic,
    str,
    bytes,
    bytearray,
    int,
    float,
    complex,
    bool,
    range,
    type(None),
    type(Ellipsis),
)


def _is_sim(obj: object) -> bool:
    module = getattr(type(obj), "__module__", "") or ""
    return module == SIM_PREFIX or module.startswith(SIM_PREFIX + ".")


def _dunder(name: str) -> bool:
    return name.startswith("__") and name.endswith("__")


def _slot_names(obj: object) -> Iterator[str]:
    """Attribute names of every ``__slots__`` entry in the MRO (private names mangled)."""
    for cls in type(obj).__mro__:
        slots = cls.__dict__.get("__slots__", ())
        for name in (slots,) if isinstance(slots, str) else slots:
            if _dunder(name):
                continue
            if name.startswith("__"):
                name = f"_{cls.__name__.lstrip('_')}{name}"
            yield name


def _edges(obj: object) -> Iterator[tuple[str, object]]:
    """(label, neighbour) pairs of one object."""
    if isinstance(obj, Mapping):
        for k, v in list(obj.items()):
            yield f"[{k!r}]", v
            yield f"<key {k!r}>", k
        return
    if isinstance(obj, list | tuple | set | frozenset | deque):
        for i, v in enumerate(list(obj)):
            yield f"[{i}]", v
        return
    seen: set[str] = set()
    try:
        attrs = dict(vars(obj))
    except TypeError:
        attrs = {}
    for name, value in attrs.items():
        if not _dunder(name):
            seen.add(name)
            yield f".{name}", value
    names = list(_slot_names(obj))
    if dataclasses.is_dataclass(obj):
        names += [f.name for f in dataclasses.fields(obj)]
    for name in names:
        if name in seen:
            continue
        seen.add(name)
        try:
            value = object.__getattribute__(obj, name)
        except Exception:  # an unset slot, or a field that is not stored
            continue
        yield f".{name}", value


def reachable_sim_objects(root: object, max_depth: int = 8) -> list[tuple[str, object]]:
    """Every object of a ``suture_bt.sim`` type reachable from ``root`` within ``max_depth``
    hops, as (access path, object) pairs, each object once, at its shortest path.

    The root itself counts (path ``""``). The walk goes on through simulator objects too, so
    the paths show what else they expose.
    """
    found: list[tuple[str, object]] = []
    seen = {id(root)}
    alive = [root]  # keeps every visited object alive, so no id() is reused during the walk
    queue: deque[tuple[str, object, int]] = deque([("", root, 0)])
    while queue:
        path, obj, depth = queue.popleft()
        if _is_sim(obj):
            found.append((path, obj))
        if depth >= max_depth or isinstance(obj, _OPAQUE):
            continue
        for label, child in _edges(obj):
            if id(child) not in seen:
                seen.add(id(child))
                alive.append(child)
                queue.append((path + label, child, depth + 1))
    return found
