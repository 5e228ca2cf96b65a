"""The campaign's PNG plots (matplotlib, headless): error distributions, time per throw,
recoveries, pass rate by joint-offset magnitude."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from suture_bt.campaign.stats import wilson


def _values(rows: list[dict[str, Any]], key: str) -> list[float]:
    """A throw field over every throw where it was measured."""
    return [t[key] for r in rows for t in r["throws"] if t.get(key) is not None]


def _hist(ax, values: list[float], title: str, unit: str, limit: float | None = None) -> None:
    """A histogram with an optional threshold line; says so when there is nothing to show."""
    if values:
        ax.hist(values, bins=min(30, max(5, len(values) // 2)), color="#4c72b0")
    else:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    if limit is not None:
        ax.axvline(limit, color="#c44e52", ls="--", label=f"SRC limit {limit:g} {unit}")
        ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(unit)


def write_plots(out: Path, rows: list[dict[str, Any]], summary: dict[str, Any]) -> list[str]:
    """Write the PNGs into ``out``; returns their file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = []
    ok = [r for r in rows if r["status"] == "ok"]

    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    _hist(axes[0, 0], _values(ok, "entry_lateral_mm"), "entry lateral error", "mm", 2.5)
    _hist(axes[0, 1], _values(ok, "exit_lateral_mm"), "exit lateral error", "mm", 2.5)
    locs = [x["task1_score_mm"] for r in ok for x in r.get("task1", []) if x.get("adopted")]
    _hist(axes[1, 0], locs, "Task 1 score of adopted localisations (base+mid+tip)", "mm")
    cal = [abs(e[j]) for r in ok for e in r["calibration_error"].values() for j in (0, 1)]
    _hist(axes[1, 1], cal, "calibration |error|, joints 1-2", "deg")
    fig.tight_layout()
    fig.savefig(out / "errors.png", dpi=90)
    plt.close(fig)
    names.append("errors.png")

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    pairs = sorted({t["pair"] for r in ok for t in r["throws"]})
    for ax, key, label in ((a1, "sim_time_s", "simulated"), (a2, "wall_time_s", "wall")):
        data = [
            [
                t[key]
                for r in ok
                for t in r["throws"]
                if t["pair"] == p and t["attempted"] and t[key] is not None
            ]
            for p in pairs
        ]
        if any(data):
            ax.boxplot([d or [np.nan] for d in data], tick_labels=[str(p) for p in pairs])
        ax.set_title(f"{label} time per throw", fontsize=10)
        ax.set_xlabel("pair")
        ax.set_ylabel("s")
    fig.tight_layout()
    fig.savefig(out / "time_per_throw.png", dpi=90)
    plt.close(fig)
    names.append("time_per_throw.png")

    fig, ax = plt.subplots(figsize=(6, 3.5))
    rec = summary["recoveries"]
    if rec:
        ax.barh(list(rec), list(rec.values()), color="#55a868")
        ax.set_xlabel("times run")
    else:
        why = (
            "no recovery branch ran"
            if summary["recovery_nodes_in_tree"]
            else ("the tree has no recovery branches yet")
        )
        ax.text(0.5, 0.5, why, ha="center", va="center", transform=ax.transAxes)
        ax.set_xticks([])
        ax.set_yticks([])
    ax.set_title(f"recoveries by kind ({summary['trials']} trials)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "recoveries.png", dpi=90)
    plt.close(fig)
    names.append("recoveries.png")

    fig, ax = plt.subplots(figsize=(7, 4))
    centres = [(b["bin"][0] + b["bin"][1]) / 2 for b in summary["by_offset"]]
    for shift, key, colour in ((-0.01, "runs", "#4c72b0"), (0.01, "throws", "#dd8452")):
        xs, ys, err = [], [], [[], []]
        for c, b in zip(centres, summary["by_offset"], strict=True):
            r = b[key]
            if r["n"]:
                lo, hi = wilson(r["k"], r["n"])
                p = r["k"] / r["n"]
                xs.append(c + shift)
                ys.append(p)
                err[0].append(max(0.0, p - lo))  # float noise at 0 % or 100 %
                err[1].append(max(0.0, hi - p))
        ax.errorbar(xs, ys, yerr=err, fmt="o", capsize=4, color=colour, label=key)
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlim(0, 1)
    ax.set_xlabel("largest joint offset / SRC bound (both arms)")
    ax.set_ylabel("pass rate (95 % Wilson)")
    ax.set_title("pass rate by joint-offset magnitude", fontsize=10)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "pass_by_offset.png", dpi=90)
    plt.close(fig)
    names.append("pass_by_offset.png")
    return names
