"""The tree half of a recording: what the behaviour tree did, tick by tick.

Entities: ``run/info`` (options, oracle label), ``run/nodes`` (path, name, class of every
node, JSON), ``run/tree`` (the tree before the first tick), ``run/result`` (the result at the
end); ``bt/nodes/<path>`` (a StateChange lane per node), ``bt/tree`` (py_trees' unicode tree
whenever it changes), ``bt/log`` (skills starting and ending, every FAILURE with its reason;
``node_path`` beside), ``bt/checks`` (the skills' confirmations), ``bt/refusals`` (the skills'
``refusals``: every look the needle sensor or localiser refused, with its reason, once: a
skill's own entry that only quotes a look its sub-skill logged, as an in-hand check's failed
localisation step does, is not logged again; a skill that looked again and went on leaves no
FAILURE behind, so the reason would be lost)
and ``bt/blackboard`` (the activity stream, READs at TRACE).
"""

from __future__ import annotations

import json
from typing import Any

import rerun as rr
from py_trees.common import Status

from suture_bt.runtime.observer import Sink, StatusChange, TickRecord, preorder

LEVEL = {
    "WRITE": rr.TextLogLevel.DEBUG,
    "INITIALISED": rr.TextLogLevel.DEBUG,
    "UNSET": rr.TextLogLevel.DEBUG,
    "READ": rr.TextLogLevel.TRACE,
    "ACCESSED": rr.TextLogLevel.TRACE,
}
#: Longest blackboard value logged (characters).
VALUE_CHARS = 120


def set_time(rec: rr.RecordingStream, tick: int, sim_time: float) -> None:
    """Both timelines: ``tick`` (1 = the first tick) and ``sim_time`` (when it ran)."""
    rec.set_time("tick", sequence=int(tick))
    rec.set_time("sim_time", duration=float(sim_time))


def is_skill(node: Any) -> bool:
    """A behaviour that runs a skill (it has ``make_skill``)."""
    return getattr(node, "skill", None) is not None or hasattr(node, "make_skill")


def skill_nodes(session: Any, record: TickRecord) -> list[Any]:
    """The behaviours this tick visited that have a skill (its report is readable)."""
    nodes = (session.observer.nodes.get(i) for i in record.visited)
    return [n for n in nodes if n is not None and getattr(n, "skill", None) is not None]


def all_checks(report: dict) -> list[dict]:
    """A report's checks and those of its finished sub-skills (``steps``), in order."""
    out = list(report.get("checks", []))
    for step in report.get("steps", []):
        out += all_checks(step)
    return out


def all_refusals(report: dict) -> list[list[str]]:
    """A report's refusal lists (``refusals``: each refused look's reason) and those of its
    finished sub-skills (``steps``), in order."""
    out = [report["refusals"]] if isinstance(report.get("refusals"), list) else []
    for step in report.get("steps", []):
        out += all_refusals(step)
    return out


class TreeSink(Sink):
    """Log the tree's ticks to ``rec`` (see the module docstring)."""

    def __init__(self, rec: rr.RecordingStream):
        self.rec = rec
        self._tree_text = ""
        self._seen: dict[int, Any] = {}  # id -> check already logged (kept: ids stay unique)
        self._refused: dict[int, tuple[list, int]] = {}  # id -> (refusal list, entries logged)
        self._reasons: dict[int, list[str]] = {}  # node id -> refusal reasons logged

    def start(self, session: Any) -> None:
        rec, opts = self.rec, session.options
        label = "ORACLE ABLATION (ground truth fed to the skills)" if opts.oracle else "vision"
        info = {
            "tree": opts.tree,
            "scene": opts.scene or "embedded SRC scene, Task 3 start",
            "seed": int(session.scene.seed),
            "mode": label,
            "policy": opts.policy,
            "tick_dt": opts.tick_dt,
        }
        rec.log("run/info", rr.TextDocument(json.dumps(info, indent=1)), static=True)
        paths = session.observer.paths
        nodes = [
            {
                "path": paths[n.id],
                "name": n.name,
                "class": type(n).__name__,
                "parent": paths.get(n.parent.id) if n.parent is not None else None,
                "skill": is_skill(n),
            }
            for n in preorder(session.root)
        ]
        rec.log("run/nodes", rr.TextDocument(json.dumps(nodes)), static=True)
        rec.log("run/tree", rr.TextDocument(session.tree_text()), static=True)

    def status_changed(self, change: StatusChange) -> None:
        set_time(self.rec, change.tick, change.sim_time)
        self.rec.log(f"bt/nodes/{change.path}", rr.StateChange(state=change.status.name))
        node, why = change.node, change.feedback
        level = None
        if change.status == Status.FAILURE:
            text = f"{node.name} FAILED" + (f": {why}" if why else "")
            worth = bool(why) or is_skill(node) or node.parent is None
            level = rr.TextLogLevel.ERROR if worth else rr.TextLogLevel.DEBUG
        elif is_skill(node) and change.status == Status.RUNNING:
            text, level = f"{node.name} started", rr.TextLogLevel.INFO
        elif (is_skill(node) or node.parent is None) and change.status == Status.SUCCESS:
            text = f"{node.name} succeeded" + (f": {why}" if why else "")
            level = rr.TextLogLevel.INFO
        if level is not None:
            self.rec.log(
                "bt/log",
                rr.TextLog(text, level=level),
                rr.AnyValues(node_path=change.path, status=change.status.name),
            )

    def tick(self, session: Any, record: TickRecord) -> None:
        rec = self.rec
        set_time(rec, record.tick, record.sim_time)
        text = session.tree_text()
        if text != self._tree_text:
            rec.log("bt/tree", rr.TextDocument(text))
            self._tree_text = text
        for item in record.activity:
            kind = str(item.activity_type)
            value = str(item.current_value)
            if len(value) > VALUE_CHARS:
                value = value[: VALUE_CHARS - 3] + "..."
            rec.log(
                "bt/blackboard",
                rr.TextLog(
                    f"{item.key} {kind} by {item.client_name}: {value}",
                    level=LEVEL.get(kind, rr.TextLogLevel.WARN),
                ),
            )
        for node in skill_nodes(session, record):
            for check in all_checks(node.skill.report):
                if id(check) in self._seen:
                    continue
                self._seen[id(check)] = check
                ok = bool(check.get("ok"))
                rec.log(
                    "bt/checks",
                    rr.TextLog(
                        f"{node.name}: {check.get('check')}: "
                        f"{'ok' if ok else 'FAILED'} -- {check.get('detail')}",
                        level=rr.TextLogLevel.INFO if ok else rr.TextLogLevel.WARN,
                    ),
                    rr.AnyValues(node_path=session.observer.paths[node.id]),
                )
            self._log_refusals(node, session.observer.paths[node.id])

    def _log_refusals(self, node: Any, path: str) -> None:
        """The refusals ``node``'s skill recorded since the last tick (``bt/refusals``), each
        once (an entry quoting another of the node's is the same refused look)."""
        new = []
        for reasons in all_refusals(node.skill.report):
            _, done = self._refused.get(id(reasons), (reasons, 0))
            new += reasons[done:]
            self._refused[id(reasons)] = (reasons, len(reasons))
        logged = self._reasons.setdefault(id(node), [])
        for reason in new:
            if any(other != reason and other in reason for other in logged + new):
                continue
            logged.append(reason)
            self.rec.log(
                "bt/refusals",
                rr.TextLog(f"{node.name}: refused: {reason}", level=rr.TextLogLevel.WARN),
                rr.AnyValues(node_path=path),
            )

    def error(self, session: Any, message: str) -> None:
        set_time(self.rec, session.ticks + 1, session.context.clock.now())
        self.rec.log("bt/log", rr.TextLog(message, level=rr.TextLogLevel.CRITICAL))

    def finish(self, session: Any, result: dict) -> None:
        set_time(self.rec, max(session.ticks, 1), session.context.clock.now())
        brief = {k: v for k, v in result.items() if k != "ports"}
        self.rec.log("run/result", rr.TextDocument(json.dumps(brief, indent=1)))
        verdict = "PASSED" if result.get("passed") else "FAILED"
        level = rr.TextLogLevel.INFO if result.get("passed") else rr.TextLogLevel.WARN
        why = result.get("error") or result.get("tree_failure") or ""
        text = f"run {verdict}: tree {result.get('tree_status')}" + (f" ({why})" if why else "")
        self.rec.log("bt/log", rr.TextLog(text, level=level))


class Flush(Sink):
    """Added last: flush and disconnect the recording when the session closes."""

    def __init__(self, rec: rr.RecordingStream):
        self.rec = rec

    def close(self, session: Any) -> None:
        self.rec.flush()
        self.rec.disconnect()
