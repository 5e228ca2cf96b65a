"""Breakpoints on node statuses (``NODE``, ``NODE=STATUS``, until-fail) and ``run_until``.

A breakpoint hits in the tick where a matching node becomes the wanted status (RUNNING by
default) or runs again into it. Node names match case-insensitively: the exact name, else a
path suffix (``Pair_1_steps/Insert_pair_1``), else a part of the name; every matching node
counts (two nodes can share a name).
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

from py_trees.common import Status

from suture_bt.runtime.observer import StatusChange, TickRecord, TreeObserver

STATUSES = {s.name: s for s in (Status.RUNNING, Status.SUCCESS, Status.FAILURE, Status.INVALID)}


class BreakpointError(ValueError):
    """A breakpoint that names no node or no status."""


def split_spec(text: str) -> tuple[str, Status]:
    """``"NODE=STATUS"`` or ``"NODE"`` (RUNNING) as (node, status); raises BreakpointError."""
    text = text.strip()
    node, status = text, Status.RUNNING
    if "=" in text:
        head, _, tail = text.rpartition("=")
        if tail.strip().upper() not in STATUSES:
            raise BreakpointError(
                f"unknown status {tail.strip()!r} in {text!r} (use {', '.join(STATUSES)})"
            )
        node, status = head.strip(), STATUSES[tail.strip().upper()]
    if not node:
        raise BreakpointError("a breakpoint needs a node name: break NODE[=STATUS]")
    return node, status


@dataclass(frozen=True)
class Breakpoint:
    """Stop when one of ``ids`` (the nodes called ``node``) becomes ``status``."""

    node: str
    status: Status
    ids: frozenset[uuid.UUID] = field(default_factory=frozenset)

    @property
    def text(self) -> str:
        return f"{self.node}={self.status.name}"

    def hits(self, record: TickRecord) -> list[StatusChange]:
        return [c for c in record.changes if c.node.id in self.ids and c.status == self.status]


def resolve(text: str, observer: TreeObserver) -> Breakpoint:
    """A breakpoint on the nodes ``text`` names in the observed tree; raises BreakpointError."""
    node, status = split_spec(text)
    found = observer.find(node)
    if not found:
        raise BreakpointError(f"no node named {node!r} in the tree (see 'tree')")
    return Breakpoint(node, status, frozenset(n.id for n in found))


def is_failure_with_reason(change: StatusChange, root: Any) -> bool:
    """A failure worth stopping for: a skill's, one that says why, or the whole tree's."""
    from suture_bt.behaviours.skill_behaviour import SkillBehaviour

    if change.status != Status.FAILURE or change.previous == Status.FAILURE:
        return False
    return change.node is root or bool(change.feedback) or isinstance(change.node, SkillBehaviour)


@dataclass
class Hit:
    """Why stepping stopped: the rule and the transitions that matched."""

    reason: str
    changes: list[StatusChange]


#: What ``run_until`` accepts: a breakpoint (text or resolved), "until-fail", a predicate
#: on the session, or a list of these.
Stop = str | Breakpoint | Callable[[Any], bool] | Iterable[Any]


def _rules(stop: Stop, observer: TreeObserver) -> list[Callable[[Any, TickRecord], Hit | None]]:
    if isinstance(stop, str | Breakpoint) or callable(stop):
        stop = [stop]
    rules = []
    for item in stop:
        if isinstance(item, str) and item.strip().lower() == "until-fail":
            rules.append(_until_fail)
        elif isinstance(item, str | Breakpoint):
            bp = resolve(item, observer) if isinstance(item, str) else item
            rules.append(_breakpoint_rule(bp))
        elif callable(item):
            rules.append(_predicate_rule(item))
        else:
            raise BreakpointError(f"cannot stop on {item!r}")
    return rules


def _breakpoint_rule(bp: Breakpoint) -> Callable[[Any, TickRecord], Hit | None]:
    def rule(session: Any, record: TickRecord) -> Hit | None:
        hits = bp.hits(record)
        return Hit(f"breakpoint {bp.text}", hits) if hits else None

    return rule


def _predicate_rule(pred: Callable[[Any], bool]) -> Callable[[Any, TickRecord], Hit | None]:
    name = getattr(pred, "__name__", "predicate")

    def rule(session: Any, record: TickRecord) -> Hit | None:
        return Hit(f"{name} is true", []) if pred(session) else None

    return rule


def _until_fail(session: Any, record: TickRecord) -> Hit | None:
    hits = [c for c in record.changes if is_failure_with_reason(c, session.root)]
    return Hit("a failure", hits) if hits else None


def run_until(session: Any, stop: Stop, max_ticks: int | None = None) -> Hit | None:
    """Tick ``session`` until a rule of ``stop`` hits (the Hit), or the run ends or
    ``max_ticks`` pass (None)."""
    rules = _rules(stop, session.observer)
    done = 0
    while not session.finished and (max_ticks is None or done < max_ticks):
        session.tick()
        done += 1
        record = session.observer.last
        if record is None or record.tick != session.ticks:
            continue  # the tick raised: no record, and the session is finished
        for rule in rules:
            hit = rule(session, record)
            if hit is not None:
                return hit
    return None
