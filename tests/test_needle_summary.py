"""The needle benchmark's set figures: refusals count as failures and are counted by kind."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import needle_summary  # noqa: E402


def test_summary_counts_refusals_as_failures_and_by_kind():
    ms = {"network": 1.0, "refine": 1.0, "fit": 1.0, "ends": 1.0, "total": 4.0}
    good = {
        "found": True,
        "pos_mm": 0.1,
        "ang_deg": 0.5,
        "ang_sym_deg": 0.5,
        "task1_mm": 0.3,
        "scenario": "free",
        "visible": 0.85,
        "depth_mm": 100.0,
        "end_decided_by": "colour",
        "ms": ms,
    }
    refused = {
        "found": False,
        "scenario": "held_psm1",
        "visible": 0.5,
        "reason": "the best pose misses the needle's outline by 0.9 px",
    }
    s = needle_summary.summary([good, refused])
    assert s["success_rate"] == 0.5 and s["not_found"] == 1
    assert s["not_found_reasons"] == {"misses the needle's outline": 1}
    assert np.isclose(s["mean_pos_err_mm"], 0.1)
    by_vis = s["by_visible_share"]
    assert set(by_vis) == {"0.00-0.60", "0.80-0.97"}
    assert by_vis["0.00-0.60"]["success_rate"] == 0.0 and by_vis["0.00-0.60"]["not_found"] == 1
    assert by_vis["0.80-0.97"]["success_rate"] == 1.0
    assert "best_ms_p95" not in s  # only from repeated calls


def test_summary_gives_the_p95_of_each_frames_fastest_call_and_counts_differing_repeats():
    rows = [
        {"found": False, "scenario": "free", "visible": 0.5, "reason": "sees no needle",
         "wall_ms": 100.0 + i, "best_ms": float(i), "repeat_differs": i == 3}
        for i in range(21)
    ]  # fmt: skip
    s = needle_summary.summary(rows)
    assert s["best_ms_p95"] == 19.0 and s["wall_ms_p95"] == 119.0
    assert s["repeat_differs"] == 1


def test_summary_gives_error_means_over_the_right_answers_beside_those_over_every_answer():
    ms = {"network": 1.0, "refine": 1.0, "fit": 1.0, "ends": 1.0, "total": 4.0}
    row = {"found": True, "ang_sym_deg": 0.5, "task1_mm": 0.3, "scenario": "free",
           "visible": 0.85, "depth_mm": 100.0, "end_decided_by": "colour", "ms": ms}  # fmt: skip
    right = row | {"pos_mm": 0.1, "ang_deg": 0.5}
    wrong = row | {"pos_mm": 1.1, "ang_deg": 9.5}
    s = needle_summary.summary([right, wrong])
    assert s["wrong"] == 1
    assert np.isclose(s["mean_pos_err_mm"], 0.6) and np.isclose(s["mean_ang_err_deg"], 5.0)
    assert np.isclose(s["right_mean_pos_err_mm"], 0.1)
    assert np.isclose(s["right_mean_ang_err_deg"], 0.5)
    none_right = needle_summary.summary([wrong])
    assert none_right["right_mean_pos_err_mm"] is None
    assert none_right["right_mean_ang_err_deg"] is None
