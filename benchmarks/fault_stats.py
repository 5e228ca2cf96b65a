"""Fault accounting for ``benchmarks/suture.py --faults``: what fired, what the tree noticed.

*Fired* comes from the world's record (``GroundTruth.fault_events()``, ground truth, after the
run). *Detected* comes only from what the tree itself saw and reported: frames the needle
sensor captured again (lost or dark), frames the calibration lost, a needle seen dropped (the
search for a dropped needle), the in-hand check's "slipped" and "drift" verdicts, and an
insertion that found its needle off the in-hand estimate (a tip reading turned more than 5°
along the arc or pivoted about the jaw) or short of the exit rule (driven on). A throw
counts under a kind when a fault of that kind fired inside its window; its outcome is the
world's score. :class:`RecoveryTime` adds up the simulated time each recovery node spent after
its first failure (its recovery branch and the attempts after it).
"""

from __future__ import annotations

from collections import defaultdict

import py_trees

from suture_bt.behaviours.recovery import RecoveryNode
from suture_bt.sim.ground_truth import GroundTruth

KINDS = ("slip", "drop", "frame_lost", "dark", "lighting", "drift")


def fired_events(world) -> list[dict]:
    """Every fault that fired (the drawn servo model is a parameter, not an event)."""
    return [
        {"kind": e.kind, "t": float(e.time), "arm": e.arm}
        for e in GroundTruth(world).fault_events()
        if e.kind != "servo_model"
    ]


def tree_detections(session) -> dict[str, int]:
    """Detections by kind, from the tree's own evidence (sensor, reports, recovery nodes)."""
    found: dict[str, int] = defaultdict(int)
    for kind, _ in getattr(session.context.sensor, "bad_frames", []):
        found["frame_lost" if kind == "lost" else "dark"] += 1
    for r in _all_reports(session.context.reports):
        found["frame_lost"] += len(r.get("frames_lost", []))
        found["drop"] += int(r.get("skill") == "find dropped needle")
        found["slip"] += int(bool(r.get("slipped")))
        found["drift"] += int(bool(r.get("drift")))
        evidence = r.get("evidence") or {}
        moved = abs(evidence.get("turn_deg", 0.0)) > 5.0 or evidence.get("pivot_deg", 0.0)
        found["slip"] += int(bool(moved or r.get("driven_on_deg")))
    return {k: v for k, v in found.items() if v}


class RecoveryTime:
    """A tick observer: simulated seconds each recovery node spent after its first failure."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self._t = 0.0

    def __call__(self, session) -> None:
        now = float(session.context.clock.now())
        dt, self._t = now - self._t, now
        for node in session.root.iterate():
            if not isinstance(node, RecoveryNode) or node.status != py_trees.common.Status.RUNNING:
                continue
            if node.attempts > 1 or node.current_child is node.recovery:
                self.seconds[node.name] += dt


def recoveries(root: py_trees.behaviour.Behaviour) -> list[dict]:
    """Recovery branches that ran: node, attempts, outcome of the last attempt."""
    out = []
    for node in root.iterate():
        if isinstance(node, RecoveryNode) and node.attempts > 1:
            out.append({"node": node.name, "attempts": node.attempts, "status": str(node.status)})
    return out


def _all_reports(reports: list[dict]):
    for r in reports:
        yield r
        yield from _all_reports(r.get("steps", []))


def throw_outcomes(result: dict, events: list[dict], windows: dict) -> list[dict]:
    """Per throw hit by a fault: the kinds that fired in its window and whether it passed."""
    passed = {t["pair"]: t["passed"] for t in result["throws"]}
    out = []
    for pair, w in windows.items():
        t0, t1 = w["t_start"], w["t_end"] if w["t_end"] is not None else result["sim_time_s"]
        kinds = sorted({e["kind"] for e in events if t0 <= e["t"] <= t1})
        if kinds:
            out.append({"pair": pair, "kinds": kinds, "passed": bool(passed.get(pair))})
    return out


def summarise_faults(runs: list[dict]) -> dict:
    """Per kind: runs it fired in, events, detections, throws hit and how many still passed."""
    table = {}
    for kind in KINDS:
        hit = [t for r in runs for t in r["fault_throws"] if kind in t["kinds"]]
        table[kind] = {
            "events": sum(1 for r in runs for e in r["faults_fired"] if e["kind"] == kind),
            "runs_fired": sum(any(e["kind"] == kind for e in r["faults_fired"]) for r in runs),
            "detected": sum(r["faults_detected"].get(kind, 0) for r in runs),
            "throws_hit": len(hit),
            "throws_hit_passed": sum(t["passed"] for t in hit),
        }
    hit_all = [t for r in runs for t in r["fault_throws"]]
    table["all"] = {
        "throws_hit": len(hit_all),
        "throws_hit_passed": sum(t["passed"] for t in hit_all),
        "recoveries_run": sum(len(r["recoveries"]) for r in runs),
        "recovery_sim_s": round(sum(sum(r.get("recovery_sim_s", {}).values()) for r in runs), 1),
    }
    return table


def recovery_costs(runs: list[dict]) -> dict[str, dict]:
    """Per recovery node (numbers as #): how often it ran and its simulated time, mean and max."""
    spent: dict[str, list[float]] = defaultdict(list)
    for r in runs:
        for name, sec in r.get("recovery_sim_s", {}).items():
            spent["".join("#" if c.isdigit() else c for c in name)].append(sec)
    return {
        k: {"ran": len(v), "sim_s_mean": round(sum(v) / len(v), 2), "sim_s_max": max(v)}
        for k, v in sorted(spent.items())
    }
