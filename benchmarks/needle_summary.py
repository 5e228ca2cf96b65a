"""The needle-pose benchmark's figures for one set (``needle_pose.py`` writes them per set):
refusals counted by kind, wrong answers and their rate over all scenes, success, errors and
stage times, per scenario and per visible share of the needle."""

from __future__ import annotations

import numpy as np

#: An answer at least this far off (mm, deg) is wrong; a right one is an answer nearer in both.
WRONG_MM, WRONG_DEG = 2.0, 5.0


def _right(r: dict, angle: str = "ang_deg") -> bool:
    """Whether row ``r`` answered within WRONG_MM and WRONG_DEG (by its ``angle`` field)."""
    return bool(r["found"] and r["pos_mm"] < WRONG_MM and r[angle] < WRONG_DEG)


def _reason_kind(reason: str) -> str:
    """A NeedleNotFound reason without its numbers, for counting refusals by kind."""
    for kind in (
        "misses the needle's outline",
        "the mask holds something else",
        "too few needle-coloured pixels",
        "sees no needle",
        "mm from the camera",
        "every start failed",
        "too few needle edge points",
        "which end is the base cannot be told",
        "the seen part leaves the pose loose",
        "the swage band starts",
        "hidden by nothing",
        "no fitted pose",
        "ends disagree with",
    ):
        if kind in reason:
            return kind
    return reason


def _group_figures(sub: list[dict]) -> dict:
    """Scenes, success rate and mean errors (over estimates) of a group of scenes."""
    est = [r for r in sub if r["found"]]
    return {
        "scenes": len(sub),
        "not_found": len(sub) - len(est),
        "success_rate": float(np.mean([_right(r) for r in sub])),
        "mean_pos_err_mm": float(np.mean([r["pos_mm"] for r in est])) if est else None,
        "mean_ang_err_deg": float(np.mean([r["ang_deg"] for r in est])) if est else None,
    }


def _by_scenario(rows: list[dict]) -> dict:
    """Figures per scenario (resting, held, in a port, ...)."""
    keys = sorted({r["scenario"] for r in rows})
    return {k: _group_figures([r for r in rows if r["scenario"] == k]) for k in keys}


#: Bins of the needle's visible share in the left image for the per-visibility figures.
VISIBLE_BINS = ((0.0, 0.6), (0.6, 0.8), (0.8, 0.97), (0.97, 1.01))


def _by_visible_share(rows: list[dict]) -> dict:
    """Figures per bin of the needle's visible share ("0.60-0.80"), empty bins left out:
    how accuracy falls as more of the needle is hidden."""
    out = {}
    for lo, hi in VISIBLE_BINS:
        sub = [r for r in rows if lo <= r["visible"] < hi]
        if sub:
            out[f"{lo:.2f}-{min(hi, 1.0):.2f}"] = _group_figures(sub)
    return out


def summary(rows: list[dict]) -> dict:
    """A set's figures from its rows: refusals by kind, wrong answers (≥ 2 mm or ≥ 5°) and their
    rate over all scenes, success, error and time statistics (errors over every answer, and
    their means over the right answers: ``right_mean_*``), and the same per scenario and per
    visible share."""
    est = [r for r in rows if r["found"]]
    reasons: dict[str, int] = {}
    for r in rows:
        if not r["found"]:
            key = _reason_kind(r["reason"])
            reasons[key] = reasons.get(key, 0) + 1
    out = {"scenes": len(rows), "not_found": len(rows) - len(est), "not_found_reasons": reasons}
    wrong = [r for r in est if not _right(r)]
    out |= {"wrong": len(wrong), "wrong_rate": len(wrong) / max(len(rows), 1)}
    out["wrong_by_scenario"] = {
        k: sum(r["scenario"] == k for r in wrong) for k in sorted({r["scenario"] for r in wrong})
    }
    walls = [r["wall_ms"] for r in rows if "wall_ms" in r]
    if walls:
        out["wall_ms_p95"] = float(np.percentile(walls, 95))
    best = [r["best_ms"] for r in rows if "best_ms" in r]
    if best:
        out["best_ms_p95"] = float(np.percentile(best, 95))
        out["repeat_differs"] = sum(bool(r.get("repeat_differs")) for r in rows)
    out["prior_refusals"] = sum(
        1 for r in rows if not r["found"] and "no fitted pose" in r.get("reason", "")
    )
    if not est:
        return out | {"success_rate": 0.0}
    pos = np.array([r["pos_mm"] for r in est])
    ang = np.array([r["ang_deg"] for r in est])
    sym = np.array([r["ang_sym_deg"] for r in est])
    t1 = np.array([r["task1_mm"] for r in est])
    ok = [_right(r) for r in rows]
    ok_sym = [_right(r, "ang_sym_deg") for r in rows]
    right = [r for r, good in zip(rows, ok, strict=True) if good]
    t = {
        k: np.array([r["ms"][k] for r in est])
        for k in ("network", "refine", "fit", "ends", "total")
    }
    return out | {
        "mean_pos_err_mm": float(pos.mean()),
        # Over the right answers only (the "means over correct answers"): the means
        # above count a wrong answer's error too.
        "right_mean_pos_err_mm": float(np.mean([r["pos_mm"] for r in right])) if right else None,
        "right_mean_ang_err_deg": float(np.mean([r["ang_deg"] for r in right])) if right else None,
        "median_pos_err_mm": float(np.median(pos)),
        "p95_pos_err_mm": float(np.percentile(pos, 95)),
        "mean_ang_err_deg": float(ang.mean()),
        "p95_ang_err_deg": float(np.percentile(ang, 95)),
        "task1_score_mm": float(t1.mean()),
        "success_rate": float(np.mean(ok)),
        "base_tip_swapped": int(np.sum((ang > 90) & (sym < 10))),
        "ends_decided_by": {
            k: sum(r["end_decided_by"] == k for r in est) for k in ("colour", "previous")
        },
        "scenarios": {
            k: n
            for k in sorted({r["scenario"] for r in rows})
            if (n := sum(r["scenario"] == k for r in rows))
        },
        "by_scenario": _by_scenario(rows),
        "by_visible_share": _by_visible_share(rows),
        "mean_ang_err_mod_swap_deg": float(sym.mean()),
        "success_rate_mod_swap": float(np.mean(ok_sym)),
        "depth_mm_range": [
            float(min(r["depth_mm"] for r in est)),
            float(max(r["depth_mm"] for r in est)),
        ],
        "ms_per_stereo_frame": {k: float(v.mean()) for k, v in t.items()}
        | {"total_p95": float(np.percentile(t["total"], 95))},
        # Per stage p95 (the tail a caller waits for is mostly the fit's).
        "ms_per_stereo_frame_p95": {k: float(np.percentile(v, 95)) for k, v in t.items()},
    }
