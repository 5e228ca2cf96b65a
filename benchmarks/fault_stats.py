"""Fault accounting for ``benchmarks/suture.py --faults``: what fired, what the tree noticed.

*Fired* comes from the world's record (``GroundTruth.fault_events()``, ground truth, after the
run). *Detected* comes only from what the tree itself saw and reported: frames the needle
sensor captured again (lost or dark), frames the calibration lost, a throw ended with "needle
dropped", and recovery nodes that ran a recovery. Slip and drift have no detector yet, so
they count as undetected unless a recovery ran in the throw they hit. A throw counts under a
kind when a fault of that kind fired inside its window; its outcome is the world's score.
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
        if "dropped" in (r.get("failure") or ""):
            found["drop"] += 1
    return dict(found)


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
    }
    return table
