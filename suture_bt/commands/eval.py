"""``suture-bt eval``: a randomized evaluation campaign scored by the SRC rules (issue 18).

N seeded trials, each a full run whose scene is drawn from the trial's seed, on a local
process pool (default) or a Ray cluster; resumable (re-running the same command skips finished
trials) and crash-isolated (a trial that raises, dies or runs out of time is an error with its
reason). Writes ``results.json``, ``summary.md`` and PNG plots into ``--out``; each trial keeps
``result.json``, ``trajectory.csv`` and the ``scene.yaml`` that replays it with ``suture-bt run``.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path

from suture_bt.campaign.randomize import Randomization
from suture_bt.trees import TREE_NAMES


def register(subparsers) -> None:
    """Add the ``eval`` subcommand."""
    p = subparsers.add_parser("eval", help="randomized evaluation campaign (SRC scoring, report)")
    p.add_argument("--trials", type=int, required=True, metavar="N", help="number of trials")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers", type=int, metavar="K", help="local trial processes (default: CPUs)"
    )
    where.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="run on Ray: 'local' starts a local instance, 'auto' or ray://host:port connects "
        "(needs pip install 'suture-bt[ray]')",
    )
    p.add_argument("--scene", metavar="FILE", help="base scene YAML (drawn fields replace its own)")
    p.add_argument(
        "--faults", default="none", metavar="PROFILE", help="fault profile: none, mild, harsh"
    )
    p.add_argument("--tree", default="multi_throw", help=f"tree: {', '.join(TREE_NAMES)}")
    p.add_argument("--oracle", action="store_true", help="ABLATION: ground truth fed to skills")
    p.add_argument("--out", metavar="DIR", default="out/eval", help="campaign directory")
    p.add_argument("--seed", type=int, default=0, metavar="N", help="seed of trial 0 (default 0)")
    p.add_argument(
        "--policy",
        choices=("stop", "continue"),
        default="stop",
        help="after a failed throw: end the trial (stop) or go on (continue)",
    )
    p.add_argument(
        "--time-budget",
        type=float,
        default=600.0,
        metavar="S",
        help="wall-clock seconds a trial may take before it is an error (default 600)",
    )
    p.add_argument(
        "--resting-fraction",
        type=float,
        default=0.0,
        metavar="F",
        help="share of trials whose needle starts resting on the tissue (default 0: "
        "all in PSM2's jaw)",
    )
    p.add_argument(
        "--resting-place",
        choices=("view", "src"),
        default="view",
        help="where a resting needle starts: drawn on the tissue in both views (default), or "
        "the SRC start pose (below this camera's image)",
    )
    jitter = Randomization()
    for flag, field, unit, what in (
        ("--phantom-xy", "phantom_xy_mm", "MM", "x/y move"),
        ("--phantom-z", "phantom_z_mm", "MM", "z move"),
        ("--phantom-yaw", "phantom_yaw_deg", "DEG", "turn about the vertical"),
        ("--phantom-tilt", "tilt_deg", "DEG", "roll and pitch"),
    ):
        p.add_argument(
            flag,
            type=float,
            default=getattr(jitter, field),
            metavar=unit,
            help=f"phantom {what} drawn within ± this (default {getattr(jitter, field):g})",
        )
    p.add_argument(
        "--brightness",
        type=float,
        nargs=2,
        default=jitter.brightness,
        metavar=("LO", "HI"),
        help=f"camera gain drawn in [LO, HI] (default {jitter.brightness[0]:g} "
        f"{jitter.brightness[1]:g})",
    )
    p.add_argument(
        "--servo",
        choices=("drawn", "nominal"),
        default="drawn",
        help="low-level servo: drawn per trial, arm and joint from the fault profile's ranges "
        "(default), or the nominal SRC servo",
    )
    p.add_argument(
        "--rerun",
        choices=("off", "save"),
        default="off",
        help="keep each trial's rerun recording as trials/NNNN/run.rrd (save)",
    )
    p.add_argument(
        "--retry-errors",
        action="store_true",
        help="run trials that ended in an error again (finished ones are skipped)",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="write the report from the trials already in DIR; run nothing",
    )
    p.set_defaults(func=run)


def _config(args):
    """The campaign configuration from the arguments (one-line errors for bad ones)."""
    import yaml

    from suture_bt.campaign.randomize import CampaignConfig, faults_supported
    from suture_bt.sim.scene import load_scene

    if args.tree not in TREE_NAMES:
        raise ValueError(f"unknown tree {args.tree!r}; choose one of: {', '.join(TREE_NAMES)}")
    raw = {}
    if args.scene:
        load_scene(args.scene)  # validates, with the scene's own one-line errors
        raw = yaml.safe_load(Path(args.scene).read_text()) or {}
    if args.faults not in ("none", "mild", "harsh"):
        raise ValueError(f"unknown fault profile {args.faults!r}; choose none, mild or harsh")
    if args.faults != "none" and not faults_supported():
        raise ValueError("fault profiles not available yet")
    if args.servo == "drawn" and not faults_supported():
        raise ValueError(
            "servo drawing not available yet (no faults: section); use --servo nominal"
        )
    return CampaignConfig(
        seed=args.seed,
        tree=args.tree,
        scene=args.scene,
        scene_raw=raw,
        faults=args.faults,
        oracle=args.oracle,
        policy=args.policy,
        rerun=args.rerun,
        randomization=Randomization(
            resting_fraction=args.resting_fraction,
            resting_place=args.resting_place,
            phantom_xy_mm=args.phantom_xy,
            phantom_z_mm=args.phantom_z,
            phantom_yaw_deg=args.phantom_yaw,
            tilt_deg=args.phantom_tilt,
            brightness=tuple(args.brightness),
            servo=args.servo,
        ),
    )


class Progress:
    """A tqdm bar over the trials with the pass rate so far (finished trials included)."""

    def __init__(self, total: int, done: int, passed: int, errors: int):
        from tqdm import tqdm

        self.base = (done, passed, errors)
        self.bar = tqdm(
            total=total, initial=done, unit="trial", file=sys.stderr, dynamic_ncols=True
        )
        self._postfix(done, passed, errors)

    def _postfix(self, seen: int, passed: int, errors: int) -> None:
        rate = f"{100 * passed / seen:.0f}%" if seen else "-"
        self.bar.set_postfix_str(f"passed {passed}/{seen} ({rate}), errors {errors}")

    def __call__(self, doc, tally) -> None:
        """After each recorded trial (``run_campaign``'s ``on_record``)."""
        done, passed, errors = self.base
        self.bar.update(1)
        self._postfix(done + tally.ran, passed + tally.passed, errors + tally.errors)

    def close(self) -> None:
        self.bar.close()


def run(args) -> int:
    """Run (or resume) the campaign and write its report; exit 1 when a trial errored."""
    from suture_bt.campaign.campaign import load_trials, run_campaign
    from suture_bt.campaign.report import write_report
    from suture_bt.campaign.runner import default_workers

    config = _config(args)
    out = Path(args.out)
    if not args.report_only:
        before = load_trials(out, args.trials) if (out / "trials").is_dir() else []
        if args.retry_errors:
            before = [d for d in before if d["status"] == "ok"]
        label = f"Ray ({args.ray})" if args.ray else f"{args.workers or default_workers()} workers"
        print(f"suture-bt eval: {args.trials} trials on {label} -> {out}", file=sys.stderr)
        progress = Progress(
            args.trials,
            len(before),
            sum(bool(d["result"] and d["result"].get("passed")) for d in before),
            sum(d["status"] != "ok" for d in before),
        )
        signal.signal(signal.SIGTERM, signal.default_int_handler)  # kill = Ctrl-C: clean up
        try:
            tally = run_campaign(
                config,
                args.trials,
                out,
                workers=args.workers or default_workers(),
                use_ray=bool(args.ray),
                ray_address=args.ray,
                budget_s=args.time_budget,
                retry_errors=args.retry_errors,
                on_record=progress,
            )
        finally:
            progress.close()
        print(
            f"ran {tally.ran} trials ({tally.skipped} already finished) in {tally.wall_s:.0f} s",
            file=sys.stderr,
        )
    summary = write_report(out, args.trials)
    print(summary.headline)
    print(f"report: {out / 'summary.md'}, {out / 'results.json'}")
    return 1 if summary.errors else 0
