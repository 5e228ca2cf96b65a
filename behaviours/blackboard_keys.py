"""Every blackboard key the suture trees use, with its type, in one place.

Behaviours publish what the skills concluded (so conditions, the debugger's ``bb`` and the
logs see it); the skills themselves share state through the :class:`TaskContext` belief.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Key:
    """A blackboard key: absolute name, the Python type of its value, what it means."""

    name: str
    type: type | tuple[type, ...]
    doc: str


NEEDLE_POSE = Key("/needle/T_world_needle", list, "last needle pose in the world (4×4 nested list)")
NEEDLE_HOLDER = Key("/needle/holder", (str, type(None)), "arm believed to hold the needle")
NEEDLE_SOURCE = Key("/needle/source", str, "what the pose came from: vision, oracle, predicted")
NEEDLE_SPREAD_DEG = Key("/needle/angle_std_deg", float, "predicted angle spread of the estimate")
NEEDLE_START = Key("/task/needle_start", str, "where the needle starts: jaw or tissue")
CURRENT_PAIR = Key("/task/pair", int, "port pair of the throw in progress (1-based)")
THROWS = Key("/task/throws", dict, "pair -> {status, reason, t_start, t_end} of every throw")


def calibrated(arm: str) -> Key:
    """Whether ``arm``'s offset is calibrated (and Δq̂ installed in its servo)."""
    return Key(f"/arms/{arm}/calibrated", bool, f"{arm} calibrated")


def offset_estimate(arm: str) -> Key:
    """``arm``'s Δq̂ (rad, rad, m)."""
    return Key(f"/arms/{arm}/offset_estimate", list, f"{arm} Δq̂ (rad, rad, m)")


ARMS = ("psm1", "psm2")
ALL_KEYS = [NEEDLE_POSE, NEEDLE_HOLDER, NEEDLE_SOURCE, NEEDLE_SPREAD_DEG, CURRENT_PAIR, THROWS]
ALL_KEYS += [NEEDLE_START]
ALL_KEYS += [calibrated(a) for a in ARMS] + [offset_estimate(a) for a in ARMS]


def check_type(key: Key, value) -> None:
    """Raise TypeError when ``value`` is not of the key's declared type."""
    if not isinstance(value, key.type):
        raise TypeError(f"blackboard {key.name}: expected {key.type}, got {type(value).__name__}")
