"""``summary.md``: a campaign's figures as Markdown, set beside the anchors (seed paper, SRC)."""

from __future__ import annotations

from typing import Any

from suture_bt.campaign.randomize import SERVO_PROFILE, servo_ranges
from suture_bt.campaign.stats import rate_text

#: What the figures are compared with (DESIGN.md §1 and §5).
ANCHORS = [
    ("SRC throw rule", "lateral ≤ 2.5 mm at entry and exit, tip ≥ 5 mm out past the exit"),
    ("SRC joint offsets", "Δq within ±5°, 5°, 5 mm on joints 1-3 (campaign draws over all of it)"),
    ("SRC success rates", "none published"),
    ("seed paper, Task 3", "four throws only with zero or tiny joint offsets; no success rate"),
    ("seed paper, needle pose", "0.3 mm / 1.1° mean error (Task 1 range, 80-200 mm)"),
    ("seed paper, calibration", "0.2 ± 0.2° per joint (joints 1-3)"),
]


def _f(v: float | None, digits: int = 2) -> str:
    """A number or a dash."""
    return "-" if v is None else f"{v:.{digits}f}"


def _sp(s: dict[str, Any], digits: int = 2) -> str:
    """``mean / p95 / max (n)`` of a spread."""
    if not s["n"]:
        return "-"
    return f"{_f(s['mean'], digits)} / {_f(s['p95'], digits)} / {_f(s['max'], digits)} (n={s['n']})"


def _randomization(config: dict[str, Any]) -> list[str]:
    """What the trials drew, in words."""
    rz = config["randomization"]
    lo, hi = rz["grasp_arc_deg"]
    rest = rz["resting_fraction"]
    place = (
        "at the SRC start pose (below the image)"
        if rz.get("resting_place") == "src"
        else "at a place drawn on the tissue in both views, face up or down"
    )
    start = f"in PSM2's jaw at a grasp arc angle drawn in [{lo:g}, {hi:g}]°" + (
        f"; {100 * rest:.0f} % of trials resting on the tissue {place}" if rest else " (jaw-only)"
    )
    faults = config["faults"]
    if rz["servo"] == "nominal":
        servo = "nominal (the SRC servo: 6 Hz, 1.5° / 0.1 mm friction)"
    else:
        ranges = servo_ranges(SERVO_PROFILE if faults == "none" else faults)
        servo = "drawn per trial, arm and joint (never told to the controller): " + ", ".join(
            f"{k} {lo:g}-{hi:g}" for k, (lo, hi) in ranges.items()
        )
    return [
        "- joint offsets of both arms: uniform over the full SRC bounds (±5°, ±5°, ±5 mm)",
        f"- needle start: {start}",
        f"- phantom: ±{rz['phantom_xy_mm']:g} mm in x/y, ±{rz['phantom_z_mm']:g} mm in z, "
        f"±{rz['phantom_yaw_deg']:g}° about the vertical, ±{rz['tilt_deg']:g}° tilt",
        f"- camera: noise σ {rz['noise_std'][0]:g}-{rz['noise_std'][1]:g} grey levels, "
        f"brightness ×{rz['brightness'][0]:g}-{rz['brightness'][1]:g}",
        f"- low-level servo: {servo}",
        f"- fault profile: {faults}",
    ]


def summary_markdown(s: dict[str, Any], plots: list[str]) -> str:
    """The whole ``summary.md``."""
    c = s["config"]
    oracle = " — **ORACLE ablation: ground truth fed to the skills**" if s["oracle"] else ""
    lines = [
        f"# Evaluation campaign: {s['trials']} trials{oracle}",
        "",
        f"Tree `{c['tree']}`, policy `{c['policy']}`, "
        f"seeds {c['seed']}..{c['seed'] + s['trials'] - 1}, "
        f"scene {c['scene'] or 'embedded SRC scene (Task 3 start)'}.",
        "",
        "Randomized per trial (from its seed):",
        "",
        *_randomization(c),
        "",
        "## Pass rates (95 % Wilson intervals)",
        "",
        "| figure | value |",
        "|---|---|",
        f"| runs passed (world's records; an error counts as a failure) | {rate_text(s['runs'])} |",
        "| runs passed by the trajectory scorer (§5 rules + Task 3 order) | "
        f"{rate_text(s['runs_src_trajectory'])} |",
        f"| throws passed (not-attempted throws count as failed) | {rate_text(s['throws'])} |",
        f"| throws passed, of those attempted | {rate_text(s['throws_attempted'])} |",
    ]
    for pair, r in s["per_pair"].items():
        lines.append(f"| pair {pair} | {rate_text(r)} |")
    lines += [
        f"| trials that ended in an error | {s['errors']} |",
        "| trials recorded after the code changed (versions mixed: not one result) | "
        f"{s.get('code_changed', 0)} |",
        "| throws where the trajectory scorer and the world disagree | "
        f"{len(s['scorer_disagreements'])} |",
        "",
        "## Errors and times (mean / p95 / max)",
        "",
        "| figure | value |",
        "|---|---|",
        f"| lateral error at the crossings, mm | {_sp(s['lateral_mm'])} |",
        f"| entry lateral, mm | {_sp(s['entry_lateral_mm'])} |",
        f"| exit lateral, mm | {_sp(s['exit_lateral_mm'])} |",
        f"| tip out past the exit, mm | {_sp(s['tip_out_mm'], 1)} |",
        f"| peak tissue strain, mm | {_sp(s['strain_mm'], 3)}; "
        f"{s['strain_over_0p5mm']} throws over 0.5 mm |",
        f"| stabs (tissue entered away from the entry port) | {s['stabs']} |",
        f"| simulated time per attempted throw, s | {_sp(s['throw_sim_time_s'], 1)} |",
        f"| wall time per attempted throw, s | {_sp(s['throw_wall_time_s'], 1)} |",
        f"| simulated time per run, s | {_sp(s['run_sim_time_s'], 1)} |",
        f"| wall time per run (tick loop), s | {_sp(s['run_wall_time_s'], 1)} |",
        f"| trial wall time, summed over trials, s | {s['trial_wall_s_total']:.0f} |",
        f"| CPU time per trial (≈ wall on an idle core), s | {_sp(s['trial_cpu_s'], 1)} |",
    ]
    for name, sp in s["calibration_abs_error"].items():
        lines.append(f"| calibration abs. error {name.replace('_', ', ')} | {_sp(sp, 3)} |")
    lines += [
        "| Task 1 score of the localisations the tree adopted (base+mid+tip), mm | "
        f"{_sp(s['task1_adopted_score_mm'])} |",
        "| Task 1 score of every localiser answer, rejected ones included, mm | "
        f"{_sp(s['task1_score_mm'])} |",
        f"| adopted: arc-centre error, mm | {_sp(s['task1_centre_mm'])} |",
        f"| adopted: rotation error, deg | {_sp(s['task1_angle_deg'])} |",
        "",
        "## Recoveries by kind",
        "",
    ]
    if s["recoveries"]:
        lines += ["| recovery | times run |", "|---|---|"]
        lines += [f"| {k} | {v} |" for k, v in s["recoveries"].items()]
    elif s["recovery_nodes_in_tree"]:
        lines.append("No recovery branch ran.")
    else:
        lines.append("The tree has no recovery branches (RecoveryNode) yet: nothing to count.")
    lines += ["", "## Faults (what fired, from the world's record after the run)", ""]
    if s.get("faults_fired"):
        lines += [
            f"{s['runs_with_a_fault']} of {s['trials'] - s['errors']} runs had at least one "
            f"fault; throws in whose window a fault fired that still passed: "
            f"{rate_text(s['throws_hit_by_a_fault'])}.",
            "",
            "| fault | fired | throws hit that passed |",
            "|---|---|---|",
        ]
        by_kind = s["throws_hit_by_kind"]
        for k, v in s["faults_fired"].items():
            hit = rate_text(by_kind[k]) if k in by_kind else "none inside a throw"
            lines.append(f"| {k} | {v} | {hit} |")
    else:
        lines.append("No fault fired.")
    lines += ["", "## Failures by reason", ""]
    if s["failures"]:
        lines += ["| failed runs: first reason (numbers as #) | runs |", "|---|---|"]
        lines += [f"| {k.replace('|', '/')} | {v} |" for k, v in s["failures"].items()]
    else:
        lines.append("No run failed.")
    if s["throw_failures"]:
        lines += ["", "| attempted throws that failed: reason | throws |", "|---|---|"]
        lines += [f"| {k.replace('|', '/')} | {v} |" for k, v in s["throw_failures"].items()]
    if s["scorer_disagreements"] or s["order_failures"]:
        lines += ["", "## Where the trajectory scorer and the world disagree", ""]
        lines += [
            "The world scores each throw inside its own time window; the trajectory scorer sees "
            "the whole run, so a port crossed outside the throws (e.g. while the needle is "
            "carried during preparation) counts against it, as the SRC rules would.",
            "",
        ]
        lines += [f"- {d}" for d in s["scorer_disagreements"]]
        lines += [f"- crossing order of {d}" for d in s["order_failures"]]
    lines += ["", "## Pass rate by joint-offset magnitude", ""]
    lines += ["| largest Δq_j / bound | runs | throws |", "|---|---|---|"]
    for b in s["by_offset"]:
        lo, hi = b["bin"]
        lines.append(f"| {lo:.2f}-{hi:.2f} | {rate_text(b['runs'])} | {rate_text(b['throws'])} |")
    lines += ["", "## Anchors", "", "| reference | figure |", "|---|---|"]
    lines += [f"| {a} | {b} |" for a, b in ANCHORS]
    if plots:
        lines += ["", "## Plots", ""] + [f"![{p}]({p})" for p in plots]
    return "\n".join(lines) + "\n"
