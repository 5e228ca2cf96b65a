"""The Ray backend against a local Ray instance started here (skipped without ray): the same
seeds give the same per-trial records as the local pool, and crashes and hangs are isolated."""

import functools
import json

import pytest

from suture_bt.campaign.campaign import load_trials, run_campaign
from suture_bt.campaign.fake_trial import fake_trial
from suture_bt.campaign.randomize import CampaignConfig
from suture_bt.campaign.runner import trial_dir

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def _comparable(out, index):
    doc = json.loads((trial_dir(out, index) / "trial.json").read_text())
    doc.pop("wall_s")
    files = {p.name: p.read_text() for p in trial_dir(out, index).iterdir() if p.suffix != ".json"}
    return doc, files, (trial_dir(out, index) / "result.json").read_text()


def test_ray_gives_the_local_pools_per_trial_results_and_isolates_crashes(tmp_path, local_ray):
    fn = functools.partial(fake_trial, plan={1: "exit", 2: "raise", 3: "fail"})
    local = run_campaign(CampaignConfig(seed=7), 5, tmp_path / "local", workers=2, trial_fn=fn)
    on_ray = run_campaign(CampaignConfig(seed=7), 5, tmp_path / "ray", use_ray=True, trial_fn=fn)
    assert local.errors == on_ray.errors == 2 and local.passed == on_ray.passed == 2
    for i in (0, 3, 4):
        assert _comparable(tmp_path / "local", i) == _comparable(tmp_path / "ray", i)
    docs = {d["index"]: d for d in load_trials(tmp_path / "ray")}
    assert docs[1]["status"] == "error" and "died" in docs[1]["reason"]
    assert docs[2]["reason"] == "raised RuntimeError: fake trial 2 raised"
    again = run_campaign(CampaignConfig(seed=7), 5, tmp_path / "ray", use_ray=True, trial_fn=fn)
    assert again.ran == 0  # resumable on Ray too


def test_a_hanging_ray_task_is_cancelled_at_its_budget(tmp_path, local_ray):
    fn = functools.partial(fake_trial, plan={0: "hang"})
    # The budget runs from submission, so it includes a fresh worker's start (after the
    # cancelled task's worker is killed): seconds on a busy machine.
    tally = run_campaign(CampaignConfig(), 2, tmp_path, use_ray=True, budget_s=8.0, trial_fn=fn)
    docs = {d["index"]: d for d in load_trials(tmp_path)}
    assert docs[0]["reason"] == "exceeded its time budget of 8 s wall"
    assert docs[1]["status"] == "ok" and tally.errors == 1
