"""Field validators of the scene file: each raises :class:`SceneError` naming the field.

Shared by :mod:`suture_bt.sim.scene` and :mod:`suture_bt.sim.fault_config`, so every section of
a scene file reports its problems the same way.
"""

from __future__ import annotations

import math
from typing import Any


class SceneError(ValueError):
    """A scene file is invalid; the message is one line naming the field."""


def _fail(path: str, expected: str, got: Any) -> None:
    raise SceneError(f"{path}: expected {expected}, got {got!r}")


def _mapping(value: Any, path: str, allowed: tuple[str, ...]) -> dict:
    if not isinstance(value, dict):
        _fail(path, "a mapping", value)
    for key in value:
        if key not in allowed:
            raise SceneError(f"{path}.{key}: unknown key (allowed: {', '.join(allowed)})")
    return value


def _number(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        _fail(path, "a finite number", value)
    return float(value)


def _positive(value: Any, path: str) -> float:
    v = _number(value, path) if isinstance(value, int | float) else None
    if v is None or v <= 0:
        _fail(path, "a positive number", value)
    return v


def _non_negative(value: Any, path: str) -> float:
    v = _number(value, path) if isinstance(value, int | float) else None
    if v is None or v < 0:
        _fail(path, "a non-negative number", value)
    return v


def _positive_int(value: Any, path: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        _fail(path, "a positive integer", value)
    return int(value)


def _vector(value: Any, path: str, n: int) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n:
        _fail(path, f"a list of {n} numbers", value)
    return tuple(_number(v, f"{path}[{i}]") for i, v in enumerate(value))


def _bool(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        _fail(path, "true or false", value)
    return value


def _probability(value: Any, path: str) -> float:
    v = _number(value, path) if isinstance(value, int | float) else None
    if v is None or not 0.0 <= v <= 1.0:
        _fail(path, "a probability in [0, 1]", value)
    return v


def _range(value: Any, path: str, lo: float = 0.0, hi: float = math.inf) -> tuple[float, float]:
    """A [low, high] pair with lo <= low <= high <= hi (a single number means [v, v])."""
    scalar = isinstance(value, int | float) and not isinstance(value, bool)
    pair = (value, value) if scalar else value
    bounds = f"[low, high] with {lo:g} <= low <= high <= {hi:g}"
    if not isinstance(pair, list | tuple) or len(pair) != 2:
        _fail(path, bounds, value)
    a, b = (_number(v, f"{path}[{i}]") for i, v in enumerate(pair))
    if not lo <= a <= b <= hi:
        _fail(path, bounds, value)
    return (a, b)


def _int_range(value: Any, path: str, lo: int = 1) -> tuple[int, int]:
    """A [low, high] pair of integers >= lo (a single integer means [n, n])."""
    pair = (value, value) if isinstance(value, int) and not isinstance(value, bool) else value
    ok = isinstance(pair, list | tuple) and len(pair) == 2
    ok = ok and all(isinstance(v, int) and not isinstance(v, bool) for v in pair)
    if not ok or not lo <= pair[0] <= pair[1]:
        _fail(path, f"an integer or [low, high] integers with {lo} <= low <= high", value)
    return (int(pair[0]), int(pair[1]))
