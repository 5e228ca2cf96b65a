"""A campaign from start to report: check/resume ``DIR``, run the missing trials, record each,
score it from its trajectory, and write the report.

``DIR/campaign.json`` holds the configuration and its fingerprint; re-running into the same
``DIR`` with other settings is refused (the trials would not be comparable), with more trials
it extends the campaign, with the same it runs only what is missing.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from suture_bt.campaign import runner
from suture_bt.campaign.randomize import CampaignConfig
from suture_bt.campaign.runner import Outcome, TrialFn


class CampaignError(ValueError):
    """The campaign cannot run as asked (one line)."""


@dataclass
class CampaignRun:
    """How a (possibly resumed) campaign went in this invocation."""

    trials: int
    skipped: int
    ran: int = 0
    errors: int = 0
    passed: int = 0
    wall_s: float = 0.0
    indices_run: list[int] = field(default_factory=list)


def write_atomic(path: Path, data: str | bytes) -> None:
    """Write a file so that a reader (or a killed campaign) never sees half of it."""
    tmp = path.with_name(path.name + ".tmp")
    if isinstance(data, bytes):
        tmp.write_bytes(data)
    else:
        tmp.write_text(data)
    os.replace(tmp, path)


def code_version() -> dict[str, Any]:
    """The git commit of the code and the files changed since (a campaign records it: trials
    are comparable only on the same code)."""
    import subprocess

    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.split("\n")
    except (OSError, subprocess.SubprocessError):
        head, dirty = "", []
    if not head and (root / "COMMIT").is_file():  # a source snapshot (git archive) says so
        return {"commit": (root / "COMMIT").read_text().strip(), "modified": [], "snapshot": True}
    return {"commit": head or None, "modified": [ln[3:] for ln in dirty if ln.strip()]}


def prepare(out: Path, config: CampaignConfig, trials: int) -> None:
    """Create ``out`` or check that it holds this campaign; record the configuration."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "campaign.json"
    old: dict[str, Any] = {}
    if path.is_file():
        try:
            old = json.loads(path.read_text())
        except ValueError:
            raise CampaignError(f"{path} is not valid JSON; use another --out") from None
        if old.get("fingerprint") != config.fingerprint:
            raise CampaignError(
                f"{out} holds a campaign with other settings (fingerprint "
                f"{old.get('fingerprint')} != {config.fingerprint}); use another --out"
            )
        trials = max(trials, int(old.get("trials", 0)))
    doc = {
        "fingerprint": config.fingerprint,
        "trials": trials,
        "config": config.to_dict(),
        # One entry per invocation: a resumed campaign may have run on newer code.
        "code": (old.get("code", []) if path.is_file() else []) + [code_version()],
    }
    write_atomic(path, json.dumps(doc, indent=2, default=str) + "\n")


def record(out: Path, outcome: Outcome) -> dict[str, Any]:
    """Write one trial's files, score its trajectory, then ``trial.json`` (last)."""
    from suture_bt.evaluation.src_scoring import score_run_dir

    spec, payload = outcome.spec, outcome.payload
    d = runner.trial_dir(out, spec["index"])
    d.mkdir(parents=True, exist_ok=True)
    doc: dict[str, Any] = {
        "index": spec["index"],
        "seed": spec["seed"],
        "draws": spec["draws"],
        "wall_s": round(outcome.wall_s, 3),
    }
    error = outcome.error
    if error is None and payload is not None and payload.get("status") != "ok":
        error = payload.get("reason") or "the trial reported an error"
        if payload.get("traceback"):
            (d / "traceback.txt").write_text(payload["traceback"])
    if error is None and payload is not None:
        for name, text in payload.get("files", {}).items():
            write_atomic(d / Path(name).name, text)
        doc["extras"] = payload.get("extras", {})
        try:
            doc["src"] = score_run_dir(d).to_dict()
        except Exception as exc:  # noqa: BLE001 - an unscorable trial is an error
            error = f"scoring failed: {type(exc).__name__}: {exc}"
    doc["status"] = "ok" if error is None else "error"
    doc["reason"] = error
    changed = code_changed_since_start(out)
    if changed is not None:
        doc["code_changed"] = changed
    write_atomic(d / "trial.json", json.dumps(doc, indent=2) + "\n")
    return doc


def code_changed_since_start(out: Path) -> dict[str, Any] | None:
    """The code now, when it differs from what this invocation of the campaign started on
    (``campaign.json``'s last ``code`` entry), else None. A trial imports the skills from the
    working tree when it starts: code edited during a campaign mixes versions, and the
    report says so."""
    try:
        started = json.loads((out / "campaign.json").read_text())["code"][-1]
    except (OSError, ValueError, KeyError, IndexError):
        return None
    now = code_version()
    return None if now == started else now


def _world_passed(out: Path, doc: dict[str, Any]) -> bool:
    """The world's verdict of a recorded trial (False when it has none)."""
    path = runner.trial_dir(out, doc["index"]) / "result.json"
    if doc["status"] != "ok" or not path.is_file():
        return False
    return bool(json.loads(path.read_text()).get("passed"))


def run_campaign(
    config: CampaignConfig,
    trials: int,
    out: Path,
    *,
    workers: int = 2,
    ray_address: str | None = None,
    use_ray: bool = False,
    budget_s: float = runner.DEFAULT_BUDGET_S,
    trial_fn: TrialFn | None = None,
    retry_errors: bool = False,
    on_record: Callable[[dict[str, Any], CampaignRun], None] | None = None,
) -> CampaignRun:
    """Run every trial of ``0..trials-1`` that is not finished in ``out``; returns the tally.
    The report is written separately (:func:`suture_bt.campaign.report.write_report`)."""
    if trials <= 0:
        raise CampaignError(f"--trials must be positive, got {trials}")
    if trial_fn is None:
        from suture_bt.campaign.trial import run_trial as trial_fn
    prepare(out, config, trials)
    specs = runner.trial_specs(config, trials)
    todo = [s for s in specs if not runner.finished(out, s["index"], retry_errors)]
    tally = CampaignRun(trials=trials, skipped=trials - len(todo))
    t0 = time.monotonic()

    def on_outcome(outcome: Outcome) -> None:
        doc = record(out, outcome)
        tally.ran += 1
        tally.indices_run.append(doc["index"])
        tally.errors += doc["status"] != "ok"
        tally.passed += _world_passed(out, doc)
        if on_record is not None:
            on_record(doc, tally)

    if use_ray:
        runner.run_ray(todo, trial_fn, on_outcome, address=ray_address, budget_s=budget_s)
    else:
        runner.run_local(todo, trial_fn, on_outcome, workers=workers, budget_s=budget_s)
    tally.wall_s = time.monotonic() - t0
    return tally


def load_trials(out: Path, trials: int | None = None) -> list[dict[str, Any]]:
    """Every recorded ``trial.json`` of a campaign (index order), with its ``result.json``
    under ``"result"`` when there is one."""
    docs = []
    for path in sorted((out / "trials").glob("*/trial.json")):
        doc = json.loads(path.read_text())
        if trials is not None and doc["index"] >= trials:
            continue
        res = path.parent / "result.json"
        doc["result"] = json.loads(res.read_text()) if doc["status"] == "ok" else None
        if doc["status"] == "ok" and not res.is_file():
            doc["status"], doc["reason"], doc["result"] = "error", "result.json missing", None
        docs.append(doc)
    return docs
