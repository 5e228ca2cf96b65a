"""One observer of a ticking tree, many sinks (the BehaviorTree.CPP ``StatusChangeLogger`` shape).

:class:`TreeObserver` is the tree's post-tick handler. After every tick it diffs every node's
status against the last tick, keeps each node's history and last feedback, and hands the
tick to its sinks: ``status_changed(change)`` per transition, then ``tick(session, record)``
once. The snapshot comes from py_trees' own :class:`~py_trees.visitors.DisplaySnapshotVisitor`
(visited path, blackboard activity stream of the tick), kept instead of printed.

It runs inside the tick at the simulated time the behaviours saw, before the world steps.
A sink that raises is dropped with a warning: recording never ends a run.
"""

from __future__ import annotations

import re
import uuid
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import py_trees
from py_trees.common import Status

#: How many transitions each node's history keeps (the debugger's ``node NAME``).
HISTORY = 200


@dataclass(frozen=True)
class StatusChange:
    """One node's transition in one tick (``previous == status``: it ran again)."""

    tick: int
    sim_time: float
    node: py_trees.behaviour.Behaviour
    path: str
    previous: Status
    status: Status
    feedback: str


@dataclass
class TickRecord:
    """What one tick did: transitions, blackboard activity, the visited path."""

    tick: int
    sim_time: float
    changes: list[StatusChange]
    activity: list[Any]
    visited: dict[uuid.UUID, Status]
    previously_visited: dict[uuid.UUID, Status]


@dataclass
class NodeHistory:
    """A node's transitions (tick, sim time, status) and its last feedback message."""

    transitions: list[tuple[int, float, Status]] = field(default_factory=list)
    feedback: str = ""
    last_active: Status = Status.INVALID


class Sink:
    """Base class of the observer's sinks; every hook is optional."""

    def start(self, session: Any) -> None:
        """Called once when the sink is added (the tree is set up, nothing ticked yet)."""

    def status_changed(self, change: StatusChange) -> None:
        """One node changed status (BehaviorTree.CPP ``StatusChangeLogger::callback``)."""

    def tick(self, session: Any, record: TickRecord) -> None:
        """A tick ended (after its ``status_changed`` calls)."""

    def error(self, session: Any, message: str) -> None:
        """The run ended with an internal error."""

    def finish(self, session: Any, result: dict) -> None:
        """The run's result document was written."""

    def close(self, session: Any) -> None:
        """The session closes: flush and release."""


class SnapshotKeeper(py_trees.visitors.DisplaySnapshotVisitor):
    """py_trees' display snapshot visitor that keeps the tick's activity instead of printing."""

    def __init__(self) -> None:
        super().__init__(display_activity_stream=True)  # enables and clears the stream
        self.activity: list[Any] = []

    def finalise(self) -> None:
        """Keep this tick's blackboard activity (the stream is cleared at the next tick)."""
        stream = py_trees.blackboard.Blackboard.activity_stream
        self.activity = list(stream.data) if stream is not None else []


def safe_part(name: str) -> str:
    """A node name as one entity-path part (letters, digits, ``_`` and ``-``)."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_") or "node"


def node_paths(root: py_trees.behaviour.Behaviour) -> dict[uuid.UUID, str]:
    """Each node's path of safe names from the root (siblings of one name get ``_2``, ...)."""
    paths = {root.id: safe_part(root.name)}

    def walk(node: py_trees.behaviour.Behaviour) -> None:
        seen: dict[str, int] = {}
        for child in node.children:
            part = safe_part(child.name)
            seen[part] = seen.get(part, 0) + 1
            if seen[part] > 1:
                part = f"{part}_{seen[part]}"
            paths[child.id] = f"{paths[node.id]}/{part}"
            walk(child)

    walk(root)
    return paths


class TreeObserver:
    """Post-tick handler of one tree: transitions, histories and the sinks (module docstring)."""

    def __init__(self, tree: py_trees.trees.BehaviourTree, clock: Any, session: Any = None):
        self.tree, self.root, self.clock, self.session = tree, tree.root, clock, session
        self.sinks: list[Sink] = []
        self.warnings: list[str] = []
        self.keeper = SnapshotKeeper()
        tree.add_visitor(self.keeper)
        tree.add_post_tick_handler(self._post_tick)
        self.nodes = {n.id: n for n in self.root.iterate()}
        self.paths = node_paths(self.root)
        self._status = {i: n.status for i, n in self.nodes.items()}
        self.history = {i: NodeHistory() for i in self.nodes}
        self.last: TickRecord | None = None

    # ---------------------------------------------------------------- sinks
    def add(self, sink: Sink) -> Sink:
        """Attach a sink and start it."""
        self.sinks.append(sink)
        self._call(sink, "start", self.session)
        return sink

    def _call(self, sink: Sink, hook: str, *args: Any) -> None:
        try:
            getattr(sink, hook)(*args)
        except Exception as exc:  # noqa: BLE001 - a broken sink must not end the run
            self.warnings.append(f"{type(sink).__name__}.{hook} failed and was dropped: {exc}")
            if sink in self.sinks:
                self.sinks.remove(sink)

    def _each(self, hook: str, *args: Any) -> None:
        for sink in list(self.sinks):
            self._call(sink, hook, *args)

    # ---------------------------------------------------------------- ticking
    def _post_tick(self, tree: py_trees.trees.BehaviourTree) -> None:
        tick, now = tree.count + 1, float(self.clock.now())
        visited = dict(self.keeper.visited)
        before = self.keeper.previously_visited
        changes = []
        for node in self.root.iterate():
            nid = node.id
            if nid not in self.nodes:  # a subtree inserted at run time
                self.nodes[nid], self.history[nid] = node, NodeHistory()
                self.paths = node_paths(self.root)
            old, new = self._status.get(nid, Status.INVALID), node.status
            again = old == new and new != Status.INVALID and nid in visited and nid not in before
            hist = self.history[nid]
            hist.feedback = node.feedback_message or hist.feedback
            if old == new and not again:
                continue
            self._status[nid] = new
            if new != Status.INVALID:
                hist.last_active = new
            hist.transitions.append((tick, now, new))
            del hist.transitions[:-HISTORY]
            changes.append(
                StatusChange(tick, now, node, self.paths[nid], old, new, node.feedback_message)
            )
        self.last = TickRecord(tick, now, changes, self.keeper.activity, visited, dict(before))
        for change in changes:
            self._each("status_changed", change)
        self._each("tick", self.session, self.last)

    def error(self, message: str) -> None:
        """The tick raised: tell the sinks."""
        self._each("error", self.session, message)

    def finish(self, result: dict) -> None:
        """The result was written: tell the sinks."""
        self._each("finish", self.session, result)

    def close(self) -> None:
        """Close every sink (once)."""
        self._each("close", self.session)
        self.sinks.clear()

    # ---------------------------------------------------------------- lookup
    def find(self, name: str) -> list[py_trees.behaviour.Behaviour]:
        """Nodes called ``name`` (case-insensitive), else whose path ends with it, else the
        nodes whose name contains it; empty when none does."""
        key = name.strip().lower()
        nodes = list(preorder(self.root))
        for test in (
            lambda n: n.name.lower() == key,
            lambda n: self.paths[n.id].lower().endswith(safe_part(key).lower()) and "/" in key,
            lambda n: key in n.name.lower(),
        ):
            found = [n for n in nodes if test(n)]
            if found:
                return found
        return []

    def names(self) -> Iterable[str]:
        """Every node's name, in tree order (parents first)."""
        return (n.name for n in preorder(self.root))


def preorder(node: py_trees.behaviour.Behaviour) -> Iterable[py_trees.behaviour.Behaviour]:
    """The node, then its descendants depth first (py_trees' ``iterate`` is children first)."""
    yield node
    for child in node.children:
        yield from preorder(child)
