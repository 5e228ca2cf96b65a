"""The ``result.json`` document of a run, and the throw table printed after it."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np


def _port_frames(phantom) -> dict[str, dict[str, list]]:
    """World frames of all ports as {"Entry1": {"p": [...], "R": [[...]...]}, ...}."""
    out = {}
    for port in phantom.ports():
        key = port.kind.capitalize() + str(port.pair)
        out[key] = {
            "p": [float(v) for v in port.position],
            "R": [[float(v) for v in row] for row in port.T[:3, :3]],
        }
    return out


def result_document(session, scores, calibration: dict, passed: bool) -> dict[str, Any]:
    """Everything a run reports (scores from the world's records; the tree's own view beside)."""
    from suture_bt.behaviours.throw_scope import failure_reason

    ctx = session.context
    tree_failure = None
    if session.root.status.value == "FAILURE":
        tree_failure = failure_reason(session.root)
    throws = []
    for s in scores:
        d = s.to_dict()
        tree = ctx.throws.get(s.pair, {})
        d["tree_status"] = tree.get("status", "NOT RUN")
        d["tree_reason"] = tree.get("reason")
        if d["failure"] == "not attempted" and (tree_failure or session.error):
            d["failure"] = f"not attempted: the run ended at {tree_failure or session.error}"
        if d["failure"] is None and not d["passed"]:
            d["failure"] = tree.get("reason") or "failed"
        if not d["passed"] and tree.get("reason") and d["failure"] != tree.get("reason"):
            d["failure"] = f"{d['failure']} (tree: {tree['reason']})"
        throws.append(d)
    opts = session.options
    return {
        "passed": bool(passed and session.error is None),
        "sim_time_s": round(ctx.clock.now(), 3),
        "wall_time_s": round(session.wall_time, 3),
        "scene": opts.scene or "embedded SRC scene, Task 3 start (needle in PSM2's jaw)",
        "seed": int(session.scene.seed),
        "oracle": bool(opts.oracle),
        "tree": opts.tree,
        "policy": opts.policy,
        "tree_status": session.root.status.value,
        "error": session.error,
        "tree_failure": tree_failure,
        "ticks": session.ticks,
        "throws": throws,
        "calibration_error": calibration,
        "localisations": int(getattr(ctx.sensor, "calls", 0)),
        "ports": _port_frames(ctx.phantom),
    }


def _clean(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_result(path: Path, result: dict[str, Any]) -> None:
    path.write_text(json.dumps(_clean(result), indent=2) + "\n")


def _f(v, digits: int = 2) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def throw_table(result: dict[str, Any]) -> str:
    """The per-throw table printed at the end of a run."""
    head = (
        "pair",
        "passed",
        "entry lat mm",
        "exit lat mm",
        "tip out mm",
        "strain mm",
        "sim s",
        "failure",
    )
    if not result["throws"]:  # a tree without throws: its own verdict
        verdict = "PASSED" if result["passed"] else "FAILED"
        lines = [
            f"run {verdict}: tree {result.get('tree_status')}, no throws, "
            f"{result['sim_time_s']:.1f} s simulated, {result['wall_time_s']:.1f} s wall"
        ]
        lines += [
            f"{k.replace('_', ' ')}: {result[k]}"
            for k in ("tree_failure", "error")
            if result.get(k)
        ]
        return "\n".join(lines)
    rows = [head]
    for t in result["throws"]:
        rows.append(
            (
                str(t["pair"]),
                "yes" if t["passed"] else "NO",
                _f(t["entry_lateral_mm"]),
                _f(t["exit_lateral_mm"]),
                _f(t["tip_out_mm"]),
                _f(t["strain_mm"], 3),
                _f(t["sim_time_s"], 1),
                t["failure"] or "",
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(head) - 1)]
    lines = []
    for r in rows:
        lines.append(
            "  ".join(c.ljust(w) for c, w in zip(r[:-1], widths, strict=True)) + "  " + r[-1]
        )
    lines.insert(1, "-" * len(lines[0]))
    verdict = "PASSED" if result["passed"] else "FAILED"
    oracle = "  [ORACLE: ground truth fed to the skills]" if result["oracle"] else ""
    lines.append(
        f"run {verdict}: {sum(t['passed'] for t in result['throws'])}/{len(result['throws'])} "
        f"throws, {result['sim_time_s']:.1f} s simulated, "
        f"{result['wall_time_s']:.1f} s wall{oracle}"
    )
    for key in ("tree_failure", "error"):
        if result.get(key):
            lines.append(f"{key.replace('_', ' ')}: {result[key]}")
    return "\n".join(lines)
