"""What the debugger prints: transitions, one node, the world as the tree believes it.

``world`` shows what the system knows (measured joints, Δq̂, the needle estimate); the true
needle is shown only for an oracle run, and labelled as ground truth.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import py_trees

from suture_bt.runtime.observer import StatusChange, TreeObserver

#: At most this many transitions are printed after a step.
MAX_CHANGE_LINES = 12


def change_line(c: StatusChange) -> str:
    """``tick 62 (1.22 s) Insert pair 1: INVALID → RUNNING -- feedback``."""
    again = " (again)" if c.previous == c.status else ""
    text = f"tick {c.tick} ({c.sim_time:.2f} s) {c.node.name}: {c.previous.name} → "
    text += f"{c.status.name}{again}"
    return text + (f" -- {c.feedback}" if c.feedback else "")


def changes_text(changes: list[StatusChange], limit: int = MAX_CHANGE_LINES) -> str:
    """The transitions, newest last, at most ``limit`` lines (older ones counted)."""
    if not changes:
        return "  (no status changes)"
    lines = [f"  {change_line(c)}" for c in changes[-limit:]]
    if len(changes) > limit:
        lines.insert(0, f"  ... {len(changes) - limit} earlier changes")
    return "\n".join(lines)


def _mm(p: np.ndarray) -> str:
    x, y, z = (1e3 * np.asarray(p, dtype=float)[:3]).tolist()
    return f"({x:+.2f}, {y:+.2f}, {z:+.2f}) mm"


def _joints(q: np.ndarray) -> str:
    q = np.asarray(q, dtype=float)
    parts = [f"{np.rad2deg(v):+.2f}°" for v in q[:2]] + [f"{1e3 * q[2]:.2f} mm"]
    parts += [f"{np.rad2deg(v):+.2f}°" for v in q[3:6]]
    return "[" + ", ".join(parts) + "]"


def _offset(dq: Any) -> str:
    dq = np.asarray(dq, dtype=float)
    return f"({np.rad2deg(dq[0]):+.2f}°, {np.rad2deg(dq[1]):+.2f}°, {1e3 * dq[2]:+.2f} mm)"


def node_text(observer: TreeObserver, nodes: Iterable[py_trees.behaviour.Behaviour]) -> str:
    """Each node's status, last feedback, transitions and (for a skill) its report's checks."""
    blocks = []
    for node in nodes:
        hist = observer.history[node.id]
        lines = [
            f"{node.name}  [{type(node).__name__}]  {observer.paths[node.id]}",
            f"  status {node.status.name} (last active: {hist.last_active.name})",
            f"  feedback: {node.feedback_message or hist.feedback or '-'}",
            f"  history ({len(hist.transitions)} transitions):",
        ]
        lines += [f"    tick {k} ({t:.2f} s) {s.name}" for k, t, s in hist.transitions[-15:]]
        skill = getattr(node, "skill", None)
        report = getattr(skill, "report", None) or {}
        if report:
            lines.append(f"  skill report ({report.get('skill', '?')}):")
            for check in report.get("checks", [])[-8:]:
                mark = "ok" if check.get("ok") else "FAILED"
                lines.append(f"    check {check.get('check')}: {mark} -- {check.get('detail')}")
            for key in ("failure", "refusals"):
                if key in report:
                    lines.append(f"    {key}: {report[key]}")
            other = sorted(k for k in report if k not in ("checks", "failure", "refusals"))
            lines.append(f"    keys: {', '.join(other)}")
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)


def world_text(session: Any, truth: Any = None) -> str:
    """Arms (measured joints, Δq̂, believed tip), the needle estimate; ``truth`` (a
    GroundTruth, oracle runs only) adds the true needle, labelled."""
    ctx = session.context
    lines = [f"t = {ctx.clock.now():.2f} s, tick {session.ticks}"]
    for name, arm in ctx.arms.items():
        q = arm.arm.measured_jp()
        lines.append(f"{name}: measured q {_joints(q)}, jaw {arm.jaw_angle():.3f} rad")
        if arm.calibrated and arm.offset_estimate is not None:
            lines.append(f"  calibrated: Δq̂ = {_offset(arm.offset_estimate)}")
        else:
            lines.append("  not calibrated")
        lines.append(f"  tip (measured + Δq̂): {_mm(arm.tip_world()[:3, 3])}")
        lines.append(f"  tip commanded:        {_mm(arm.commanded_tip_world()[:3, 3])}")
    b = ctx.belief
    if b is None:
        lines.append("needle: no estimate yet")
    else:
        lines.append(
            f"needle estimate: {_mm(b.T_world_needle[:3, 3])} from {b.source} at {b.stamp:.2f} s,"
            f" holder {b.holder or 'none'}, spread {b.angle_std_deg:.2f}°"
        )
        predicted = ctx.predicted_needle()
        if predicted is not None and b.holder is not None:
            lines.append(f"  predicted now (moved with {b.holder}): {_mm(predicted[:3, 3])}")
    if truth is not None:
        T = truth.needle_pose()
        line = f"[GROUND TRUTH, oracle run] needle: {_mm(T[:3, 3])}"
        if b is not None:
            err = 1e3 * np.linalg.norm(T[:3, 3] - ctx.predicted_needle()[:3, 3])
            line += f", estimate off by {err:.2f} mm"
        lines.append(line)
    return "\n".join(lines)
