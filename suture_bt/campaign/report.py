"""A campaign's report: ``results.json`` (per trial, per throw), ``summary.md`` and PNG plots.

Built from what the trials recorded (``trials/NNNN/trial.json`` + ``result.json``), so it can be
rebuilt at any time (``suture-bt eval --report-only``). Two verdicts stand side by side: the
world's (its own crossing records, tissue entries and strain) and the trajectory scorer's
(:mod:`suture_bt.evaluation.src_scoring`, from ``trajectory.csv`` alone); a throw on which they
disagree is listed. A trial that ended in an error counts as a failed run.
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from suture_bt.campaign.campaign import load_trials, write_atomic
from suture_bt.campaign.randomize import offset_magnitude
from suture_bt.campaign.stats import rate, reason_key, spread

#: Normalised offset-magnitude bins (largest |Δq_j| / bound over both arms) for the plot.
OFFSET_BINS = (0.0, 0.7, 0.85, 0.95, 1.0)


@dataclass
class Summary:
    """The headline of a campaign (the rest is in ``results.json``)."""

    headline: str
    errors: int
    doc: dict[str, Any]


def _throw_row(trial: dict[str, Any], t: dict[str, Any]) -> dict[str, Any]:
    """One throw: the world's figures, the trajectory scorer's, and whether they agree."""
    src = {s["pair"]: s for s in trial.get("src", {}).get("throws", [])}.get(t["pair"], {})
    extras = trial.get("extras", {})
    world_src_rules = t["passed"] or (t.get("stab_mm") is not None and _only_stab(t["failure"]))
    return {
        "pair": t["pair"],
        "passed": bool(t["passed"]),
        "attempted": not str(t.get("failure") or "").startswith("not attempted"),
        "src_passed": src.get("passed"),
        "agree": src.get("passed") == world_src_rules,
        "entry_lateral_mm": t.get("entry_lateral_mm"),
        "exit_lateral_mm": t.get("exit_lateral_mm"),
        "tip_out_mm": t.get("tip_out_mm"),
        "src_entry_lateral_mm": src.get("entry_lateral_mm"),
        "src_exit_lateral_mm": src.get("exit_lateral_mm"),
        "src_tip_out_mm": src.get("tip_out_mm"),
        "src_failure": src.get("failure"),
        "src_crossing_t": [src.get("entry_t"), src.get("exit_t")],
        "strain_mm": t.get("strain_mm"),
        "stab_mm": t.get("stab_mm"),
        "sim_time_s": t.get("sim_time_s"),
        "wall_time_s": extras.get("throw_wall_s", {}).get(str(t["pair"])),
        "failure": t.get("failure"),
        "faults": _faults_in(extras, t["pair"]),
    }


def _faults_in(extras: dict[str, Any], pair: int) -> list[str]:
    """Kinds of the faults that fired inside this throw's window (ground truth, after the run)."""
    t0, t1 = (extras.get("throw_windows", {}).get(str(pair)) or [None, None])[:2]
    if t0 is None:
        return []
    end = float("inf") if t1 is None else t1
    return sorted({f["kind"] for f in extras.get("faults_fired", []) if t0 <= f["t"] <= end})


def _disagreement(trial: dict[str, Any], t: dict[str, Any]) -> str:
    """One line on a throw the two scorers judge differently."""
    world = "passed" if t["passed"] else f"failed ({t['failure']})"
    src = "passed" if t["src_passed"] else f"failed ({t['src_failure']})"
    t0, t1 = t["src_crossing_t"]
    when = "" if t0 is None else f", scored crossings at t = {t0:.2f}-{t1 or t0:.2f} s"
    return f"trial {trial['index']} pair {t['pair']}: world {world}; trajectory {src}{when}"


def _run_failure(row: dict[str, Any]) -> str:
    """Why a run failed, numbers as ``#``: its error, where the tree stopped, or its first
    failed throw."""
    if row["status"] != "ok":
        return "trial error: " + reason_key(row["error"])
    if row.get("run_error"):
        return "run error: " + reason_key(row["run_error"])
    failed = [t for t in row["throws"] if not t["passed"] and t["attempted"]]
    if failed:
        return f"throw failed: {reason_key(failed[0]['failure'])}"
    if row.get("tree_failure"):
        return "tree stopped: " + reason_key(row["tree_failure"])
    return "failed (no reason recorded)"


def _only_stab(failure: str | None) -> bool:
    """True when a world failure lists nothing but a stab (the SRC rules have no stab)."""
    parts = [p.strip() for p in str(failure or "").split(";") if p.strip()]
    return bool(parts) and all(p.startswith("stab") for p in parts)


def trial_row(trial: dict[str, Any]) -> dict[str, Any]:
    """One trial for ``results.json``."""
    draws = trial["draws"]
    row: dict[str, Any] = {
        "index": trial["index"],
        "seed": trial["seed"],
        "status": trial["status"],
        "error": trial.get("reason"),
        "trial_wall_s": trial.get("wall_s"),
        "offsets": {a: v.get("joint_offset") for a, v in draws.get("arms", {}).items()},
        "offset_magnitude": round(offset_magnitude(draws), 4),
        "needle": draws.get("needle"),
        "phantom": draws.get("phantom"),
        "camera": draws.get("camera"),
        "servo": draws.get("servo", "nominal"),
        "faults": draws.get("faults", "none"),
        "code_changed": "code_changed" in trial,
    }
    result = trial.get("result")
    if result is None:
        return row | {"passed": False, "throws": []}
    extras, src = trial.get("extras", {}), trial.get("src", {})
    locs = extras.get("localisations", [])
    row |= {
        "passed": bool(result["passed"]),
        "src_passed": src.get("passed"),
        "src_order_ok": src.get("order_ok"),
        "src_sequence": src.get("sequence"),
        "oracle": bool(result.get("oracle")),
        "sim_time_s": result.get("sim_time_s"),
        "run_wall_s": result.get("wall_time_s"),
        "trial_cpu_s": extras.get("trial_cpu_s"),
        "tree_failure": result.get("tree_failure"),
        "run_error": result.get("error"),
        "calibration_error": result.get("calibration_error", {}),
        "localisations": len(locs),
        "localisation_refusals": extras.get("localisation_refusals"),
        "task1_score_mm": spread(x["task1_score_mm"] for x in locs),
        "task1": locs,
        "recoveries": extras.get("recoveries", {}),
        "recovery_nodes": extras.get("recovery_nodes"),
        "faults_fired": dict(Counter(f["kind"] for f in extras.get("faults_fired", []))),
        "throws": [_throw_row(trial, t) for t in result.get("throws", [])],
    }
    return row


def summarise(rows: list[dict[str, Any]], config: dict[str, Any]) -> dict[str, Any]:
    """Campaign figures from the trial rows (see ``summary.md`` for their meaning)."""
    ok = [r for r in rows if r["status"] == "ok"]
    throws = [t for r in ok for t in r["throws"]]
    pairs = sorted({t["pair"] for t in throws})
    lat = [t[k] for t in throws for k in ("entry_lateral_mm", "exit_lateral_mm")]
    cal = {j: [] for j in range(3)}
    for r in ok:
        for err in r["calibration_error"].values():
            for j in range(3):
                cal[j].append(abs(err[j]))
    locs = [x for r in ok for x in r.get("task1", [])]
    failures: Counter[str] = Counter()
    throw_failures: Counter[str] = Counter()
    for r in rows:
        if not r["passed"]:
            failures[_run_failure(r)] += 1
        for t in r["throws"]:
            if t["attempted"] and not t["passed"]:
                throw_failures[reason_key(t["failure"])] += 1
    recoveries: Counter[str] = Counter()
    fired: Counter[str] = Counter()
    for r in ok:
        recoveries.update(r.get("recoveries", {}))
        fired.update(r.get("faults_fired", {}))
    hit = [t for t in throws if t.get("faults")]
    hit_by_kind = {
        k: rate(
            sum(t["passed"] for t in hit if k in t["faults"]), sum(k in t["faults"] for t in hit)
        )
        for k in sorted({k for t in hit for k in t["faults"]})
    }
    by_offset = []
    for lo, hi in zip(OFFSET_BINS[:-1], OFFSET_BINS[1:], strict=True):
        inside = [
            r
            for r in rows
            if lo <= r["offset_magnitude"] < hi or (hi == 1.0 and r["offset_magnitude"] == 1.0)
        ]
        tin = [t for r in inside for t in r["throws"]]
        by_offset.append(
            {
                "bin": [lo, hi],
                "runs": rate(sum(r["passed"] for r in inside), len(inside)),
                "throws": rate(sum(t["passed"] for t in tin), len(tin)),
            }
        )
    return {
        "trials": len(rows),
        "errors": len(rows) - len(ok),
        "code_changed": sum(bool(r.get("code_changed")) for r in rows),
        "oracle": any(r.get("oracle") for r in ok),
        "runs": rate(sum(r["passed"] for r in rows), len(rows)),
        "runs_src_trajectory": rate(sum(bool(r.get("src_passed")) for r in rows), len(rows)),
        "throws": rate(sum(t["passed"] for t in throws), len(throws)),
        "throws_attempted": rate(
            sum(t["passed"] for t in throws if t["attempted"]),
            sum(t["attempted"] for t in throws),
        ),
        "per_pair": {
            str(p): rate(
                sum(t["passed"] for t in throws if t["pair"] == p),
                sum(t["pair"] == p for t in throws),
            )
            for p in pairs
        },
        "scorer_disagreements": [
            _disagreement(r, t) for r in ok for t in r["throws"] if not t["agree"]
        ],
        "order_failures": [
            f"trial {r['index']}: {', '.join(r.get('src_sequence') or []) or 'no crossings'}"
            for r in ok
            if r.get("src_order_ok") is False and r["passed"]
        ],
        "lateral_mm": spread(lat),
        "entry_lateral_mm": spread(t["entry_lateral_mm"] for t in throws),
        "exit_lateral_mm": spread(t["exit_lateral_mm"] for t in throws),
        "tip_out_mm": spread(t["tip_out_mm"] for t in throws),
        "strain_mm": spread(t["strain_mm"] for t in throws),
        "strain_over_0p5mm": sum((t["strain_mm"] or 0.0) > 0.5 for t in throws),
        "stabs": sum(t["stab_mm"] is not None for t in throws),
        "throw_sim_time_s": spread(t["sim_time_s"] for t in throws if t["attempted"]),
        "throw_wall_time_s": spread(t["wall_time_s"] for t in throws if t["attempted"]),
        "run_sim_time_s": spread(r["sim_time_s"] for r in ok),
        "run_wall_time_s": spread(r["run_wall_s"] for r in ok),
        "trial_wall_s_total": round(sum(r["trial_wall_s"] or 0.0 for r in rows), 1),
        "trial_cpu_s": spread(r.get("trial_cpu_s") for r in ok),
        "calibration_abs_error": {
            name: spread(cal[j]) for j, name in enumerate(("q1_deg", "q2_deg", "q3_mm"))
        },
        "task1_score_mm": spread(x["task1_score_mm"] for x in locs),
        "task1_adopted_score_mm": spread(x["task1_score_mm"] for x in locs if x.get("adopted")),
        "task1_centre_mm": spread(x["centre_mm"] for x in locs if x.get("adopted")),
        "task1_angle_deg": spread(x["angle_deg"] for x in locs if x.get("adopted")),
        "recoveries": dict(recoveries.most_common()),
        "faults_fired": dict(fired.most_common()),
        "runs_with_a_fault": sum(bool(r.get("faults_fired")) for r in ok),
        "throws_hit_by_a_fault": rate(sum(t["passed"] for t in hit), len(hit)),
        "throws_hit_by_kind": hit_by_kind,
        "recovery_nodes_in_tree": max((r.get("recovery_nodes") or 0 for r in ok), default=0),
        "failures": dict(failures.most_common()),
        "throw_failures": dict(throw_failures.most_common()),
        "by_offset": by_offset,
        "config": config,
    }


def write_report(out: Path, trials: int | None = None) -> Summary:
    """Write ``results.json``, ``summary.md`` and the plots for the trials recorded in ``out``
    (the first ``trials`` of them when given)."""
    from suture_bt.campaign.plots import write_plots
    from suture_bt.campaign.summary_md import summary_markdown

    out = Path(out)
    meta = json.loads((out / "campaign.json").read_text())
    rows = [trial_row(t) for t in load_trials(out, trials)]
    summary = summarise(rows, meta["config"])
    summary["trials_planned"] = trials if trials is not None else meta.get("trials")
    plots = write_plots(out, rows, summary)
    doc = {"campaign": meta, "summary": summary, "trials": rows}
    write_atomic(out / "results.json", json.dumps(doc, indent=2) + "\n")
    write_atomic(out / "summary.md", summary_markdown(summary, plots))
    from suture_bt.campaign.stats import rate_text

    oracle = " [ORACLE]" if summary["oracle"] else ""
    headline = (
        f"{summary['trials']} trials{oracle}: runs passed {rate_text(summary['runs'])}, "
        f"throws {rate_text(summary['throws'])}, errors {summary['errors']}"
    )
    return Summary(headline, summary["errors"], doc)
