"""Evaluation campaigns with a stand-in trial (milliseconds each): draws, crash isolation,
time budgets, resuming (also after the campaign process is killed), the report."""

import functools
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from suture_bt.campaign.campaign import CampaignError, load_trials, run_campaign
from suture_bt.campaign.fake_trial import fake_trial
from suture_bt.campaign.randomize import (
    CampaignConfig,
    Randomization,
    draw,
    faults_supported,
    offset_magnitude,
    phantom_pose_in_view,
    trial_scene_dict,
)
from suture_bt.campaign.report import write_report
from suture_bt.campaign.runner import trial_dir
from suture_bt.campaign.stats import reason_key, wilson
from suture_bt.sim.scene import scene_from_dict


def _fake(plan=None, sleep=0.0):
    return functools.partial(fake_trial, plan=plan or {}, sleep=sleep)


def test_draws_are_seeded_in_bounds_and_valid_scenes():
    config = CampaignConfig(seed=100)
    a, b = draw(config, 3), draw(config, 3)
    assert a == b and a != draw(config, 4) and a["seed"] == 103
    for i in range(30):
        d = draw(config, i)
        for arm in ("psm1", "psm2"):
            assert np.all(np.abs(d["arms"][arm]["joint_offset"]) <= [5, 5, 5])
        assert d["needle"]["start"] == "in_psm2_jaw"  # jaw-only by default
        assert 145 <= d["needle"]["grasp_arc_angle_deg"] <= 165
        roll, pitch, yaw = np.rad2deg(d["phantom"]["rpy"])
        assert max(abs(roll), abs(pitch)) <= 1.5 and abs(yaw) <= 3.0
        assert np.all(np.abs(d["phantom"]["position"]) <= [0.003, 0.003, 0.0015])
        assert 0.0 <= offset_magnitude(d) <= 1.0
        scene = scene_from_dict(trial_scene_dict(config, i))  # the scene parser accepts it
        assert scene.seed == 100 + i
    offsets = np.array([draw(config, i)["arms"]["psm1"]["joint_offset"] for i in range(200)])
    assert offsets.min(axis=0).max() < -4.5 and offsets.max(axis=0).min() > 4.5  # full range


def test_the_resting_fraction_changes_only_the_needle_start():
    base = CampaignConfig()
    resting = CampaignConfig(randomization=Randomization(resting_fraction=1.0))
    src = CampaignConfig(randomization=Randomization(resting_fraction=1.0, resting_place="src"))
    for i in range(5):
        a, b = draw(base, i), draw(resting, i)
        assert b["needle"]["start"] == "pose" and draw(src, i)["needle"] == {"start": "resting"}
        assert a["arms"] == b["arms"] and a["phantom"] == b["phantom"]
        scene_from_dict(trial_scene_dict(resting, i))
    with pytest.raises(ValueError, match="tilt"):
        Randomization(tilt_deg=20.0)
    with pytest.raises(ValueError, match="resting place"):
        Randomization(resting_place="anywhere")
    with pytest.raises(ValueError, match="brightness"):
        Randomization(brightness=(1.5, 0.5))


def test_default_phantom_draws_are_kept_and_wide_ones_keep_every_port_in_view():
    from suture_bt.campaign.randomize import PORT_MARGIN_PX, _rng
    from suture_bt.campaign.resting_start import in_view
    from suture_bt.geometry import PhantomModel
    from suture_bt.sim.camera import stereo_model
    from suture_bt.transforms import pose_to_transform

    config = CampaignConfig(seed=9966575095)
    for i in range(30):  # the first draw, as campaigns before the view check drew it
        g = _rng(9966575095 + i, "phantom")
        xy, z = g.uniform(-1.0, 1.0, 2) * 3e-3, g.uniform(-1.0, 1.0) * 1.5e-3
        assert draw(config, i)["phantom"]["position"] == [round(v, 6) for v in (*xy, z)]
    wide = Randomization(phantom_xy_mm=25, phantom_z_mm=5, phantom_yaw_deg=25, tilt_deg=6)
    camera, moved = stereo_model(1920, 1080), 0
    for i in range(30):
        ph = draw(CampaignConfig(seed=9600000, randomization=wide), i)["phantom"]
        T = pose_to_transform(ph["position"], ph["rpy"])
        ports = np.array([port.position for port in PhantomModel(T).ports()])
        assert in_view(camera, ports, PORT_MARGIN_PX)
        moved += np.hypot(*ph["position"][:2]) > 0.015
    assert moved >= 5  # the wide range is still used


def test_a_phantom_pose_drawn_about_a_base_pose_stays_in_its_ranges_with_ports_in_view():
    from suture_bt.campaign.randomize import PORT_MARGIN_PX
    from suture_bt.campaign.resting_start import in_view
    from suture_bt.geometry import PhantomModel
    from suture_bt.sim.camera import stereo_model
    from suture_bt.transforms import pose_to_transform

    rz = Randomization(phantom_xy_mm=20, phantom_z_mm=5, phantom_yaw_deg=20, tilt_deg=5)
    camera, p0, r0 = stereo_model(1920, 1080), (0.001, -0.002, 0.0), (0.0, 0.0, 0.1)
    g = np.random.default_rng(5)
    for _ in range(20):
        pose = phantom_pose_in_view(rz, g, camera, p0, r0)
        dp, dr = np.subtract(pose["position"], p0), np.degrees(np.subtract(pose["rpy"], r0))
        assert np.all(np.abs(dp[:2]) <= 0.020 + 1e-9) and abs(dp[2]) <= 0.005 + 1e-9
        assert np.all(np.abs(dr[:2]) <= 5 + 1e-6) and abs(dr[2]) <= 20 + 1e-6
        T = pose_to_transform(pose["position"], pose["rpy"])
        ports = np.array([port.position for port in PhantomModel(T).ports()])
        assert in_view(camera, ports, PORT_MARGIN_PX)
    far = Randomization(phantom_xy_mm=50, phantom_z_mm=50, phantom_yaw_deg=45, tilt_deg=15)
    with pytest.raises(ValueError, match="no phantom pose with every port in view"):
        phantom_pose_in_view(far, g, camera, (0.3, 0.0, 0.0))


def test_resting_starts_lie_flat_on_the_tissue_in_both_views_and_move_with_the_phantom():
    from suture_bt.campaign.resting_start import MARGIN_PX, in_view
    from suture_bt.geometry import NeedleModel
    from suture_bt.sim.camera import stereo_model
    from suture_bt.transforms import invert, pose_to_transform

    wide = Randomization(resting_fraction=1.0, phantom_xy_mm=20, phantom_yaw_deg=20, tilt_deg=5)
    config = CampaignConfig(seed=40, randomization=wide)
    camera, arc = stereo_model(1920, 1080), NeedleModel().centerline(25)
    faces = set()
    for i in range(20):
        d = draw(config, i)
        T_wp = pose_to_transform(d["phantom"]["position"], d["phantom"]["rpy"])
        T = pose_to_transform(d["needle"]["position"], d["needle"]["rpy"])
        local = invert(T_wp) @ T
        assert abs(local[2, 2]) > 0.999  # the needle's plane is the tissue's
        assert 0.022 <= abs(local[0, 3]) <= 0.036  # beside the ridge
        ends = (local @ np.c_[NeedleModel().centerline(25), np.ones(25)].T)[:2].T
        assert np.all(np.abs(ends[:, 0]) <= 0.042) and np.all(ends[:, 1] >= -0.052)  # on the block
        assert np.all(ends[:, 1] <= 0.072)
        faces.add(bool(local[2, 2] < 0))
        assert in_view(camera, arc @ T[:3, :3].T + T[:3, 3], MARGIN_PX)
    assert faces == {True, False}  # face up and face down both drawn


def test_a_base_scene_file_is_kept_where_nothing_is_drawn():
    raw = {"camera": {"width": 640, "height": 480}, "phantom": {"position": [0.01, 0.0, 0.0]}}
    config = CampaignConfig(scene_raw=raw)
    d = trial_scene_dict(config, 0)
    assert d["camera"]["width"] == 640 and "noise_std" in d["camera"]
    assert abs(d["phantom"]["position"][0] - 0.01) <= 0.003  # jittered about the file's pose
    assert CampaignConfig(scene_raw=raw).fingerprint != CampaignConfig().fingerprint


def test_trials_that_raise_die_segfault_or_hang_are_errors_and_the_rest_finish(tmp_path):
    plan = {1: "raise", 2: "exit", 3: "segv", 4: "hang", 5: "fail"}
    tally = run_campaign(
        CampaignConfig(), 8, tmp_path, workers=2, budget_s=2.0, trial_fn=_fake(plan, 0.05)
    )
    assert tally.ran == 8 and tally.errors == 4 and tally.passed == 3
    docs = {d["index"]: d for d in load_trials(tmp_path)}
    assert [docs[i]["status"] for i in range(8)] == ["ok"] + ["error"] * 4 + ["ok"] * 3
    assert docs[1]["reason"] == "raised RuntimeError: fake trial 1 raised"
    assert (trial_dir(tmp_path, 1) / "traceback.txt").is_file()
    assert docs[2]["reason"] == "the trial process exited with status 3 before reporting"
    assert docs[3]["reason"] == "the trial process died (SIGSEGV)"
    assert docs[4]["reason"] == "exceeded its time budget of 2 s wall"
    assert docs[5]["result"]["passed"] is False and docs[5]["src"]["passed"] is False
    assert docs[0]["src"]["passed"] is True  # the fake tip crosses Entry1 then Exit1
    for i in (0, 5, 6, 7):
        assert {"result.json", "trajectory.csv", "trial.json"} <= {
            p.name for p in trial_dir(tmp_path, i).iterdir()
        }


def test_rerunning_skips_finished_trials_and_extends_the_campaign(tmp_path):
    fn = _fake({2: "raise"})
    first = run_campaign(CampaignConfig(), 4, tmp_path, workers=2, trial_fn=fn)
    assert sorted(first.indices_run) == [0, 1, 2, 3]
    stamps = {i: (trial_dir(tmp_path, i) / "trial.json").stat().st_mtime_ns for i in range(4)}
    again = run_campaign(CampaignConfig(), 4, tmp_path, workers=2, trial_fn=fn)
    assert again.ran == 0 and again.skipped == 4
    more = run_campaign(CampaignConfig(), 6, tmp_path, workers=2, trial_fn=fn)
    assert sorted(more.indices_run) == [4, 5]
    for i, ns in stamps.items():
        assert (trial_dir(tmp_path, i) / "trial.json").stat().st_mtime_ns == ns
    retry = run_campaign(CampaignConfig(), 6, tmp_path, trial_fn=_fake(), retry_errors=True)
    assert retry.indices_run == [2] and retry.errors == 0


def test_a_campaign_dir_with_other_settings_is_refused(tmp_path):
    run_campaign(CampaignConfig(), 1, tmp_path, trial_fn=_fake())
    with pytest.raises(CampaignError, match="other settings"):
        run_campaign(CampaignConfig(seed=5), 1, tmp_path, trial_fn=_fake())


def test_a_killed_campaign_completes_only_its_missing_trials_when_rerun(tmp_path):
    script = textwrap.dedent(
        f"""
        import functools
        from pathlib import Path
        from suture_bt.campaign.campaign import run_campaign
        from suture_bt.campaign.fake_trial import fake_trial
        from suture_bt.campaign.randomize import CampaignConfig
        if __name__ == "__main__":
            fn = functools.partial(fake_trial, plan={{}}, sleep=0.4)
            run_campaign(CampaignConfig(), 8, Path({str(tmp_path)!r}), workers=1, trial_fn=fn)
        """
    )
    (tmp_path / "campaign_script.py").write_text(script)
    proc = subprocess.Popen([sys.executable, str(tmp_path / "campaign_script.py")])
    deadline = time.monotonic() + 60
    while len(list(tmp_path.glob("trials/*/trial.json"))) < 2:
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done = {int(p.parent.name) for p in tmp_path.glob("trials/*/trial.json")}
    assert 2 <= len(done) < 8
    rerun = run_campaign(CampaignConfig(), 8, tmp_path, workers=2, trial_fn=_fake())
    assert sorted(rerun.indices_run) == sorted(set(range(8)) - done)
    assert [d["status"] for d in load_trials(tmp_path)] == ["ok"] * 8


def test_the_report_counts_passes_errors_and_reasons_with_wilson_intervals(tmp_path):
    plan = {1: "fail", 2: "fail", 3: "raise"}
    run_campaign(CampaignConfig(), 10, tmp_path, workers=2, trial_fn=_fake(plan))
    summary = write_report(tmp_path, 10)
    s = summary.doc["summary"]
    assert s["runs"]["k"] == 7 and s["runs"]["n"] == 10 and summary.errors == 1
    assert s["runs"]["ci95"] == pytest.approx(wilson(7, 10), abs=1e-4)
    assert s["runs_src_trajectory"]["k"] == 7 and s["scorer_disagreements"] == []
    assert s["throws"]["n"] == 9  # the errored trial has no throws
    assert s["failures"]["trial error: raised RuntimeError: fake trial # raised"] == 1
    assert s["failures"]["throw failed: no exit crossing of exit# after entry#"] == 2
    assert s["throw_failures"] == {"no exit crossing of exit# after entry#": 2}
    md = (tmp_path / "summary.md").read_text()
    assert "7/10 (70 %, CI 40-89 %)" in md and "Anchors" in md and "0.3 mm / 1.1°" in md
    for png in ("errors.png", "time_per_throw.png", "recoveries.png", "pass_by_offset.png"):
        assert (tmp_path / png).read_bytes()[:4] == b"\x89PNG"
    # faults: odd trials had a slip inside throw 1 (trial 1 failed it) and a frame lost after
    assert s["faults_fired"] == {"slip": 4, "frame_lost": 4} and s["runs_with_a_fault"] == 4
    assert (s["throws_hit_by_a_fault"]["k"], s["throws_hit_by_a_fault"]["n"]) == (3, 4)
    assert set(s["throws_hit_by_kind"]) == {"slip"}
    assert "| slip | 4 | 3/4" in md and "| frame_lost | 4 | none inside a throw |" in md
    rows = json.loads((tmp_path / "results.json").read_text())["trials"]
    assert rows[1]["throws"][0]["faults"] == ["slip"] and rows[2]["throws"][0]["faults"] == []
    assert [r["index"] for r in rows] == list(range(10)) and rows[3]["status"] == "error"
    assert rows[0]["throws"][0]["agree"] and rows[0]["offsets"]["psm1"]


def test_wilson_interval_and_reason_grouping():
    assert wilson(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    assert wilson(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson(0, 0) == (0.0, 1.0) and wilson(0, 3)[0] == 0.0 and wilson(7, 7)[1] == 1.0
    assert reason_key("entry lateral 3.1 mm > 2.5 mm") == "entry lateral # mm > # mm"


def test_fault_profiles_and_servo_draws_go_into_the_scenes_faults_section(tmp_path, capsys):
    if not faults_supported():
        from suture_bt.cli import main

        status = main(["eval", "--trials", "1", "--faults", "mild", "--out", str(tmp_path)])
        assert status == 1
        err = capsys.readouterr().err.strip()
        assert err == "suture-bt: error: fault profiles not available yet"
        return
    drawn = scene_from_dict(trial_scene_dict(CampaignConfig(), 0))  # servo drawn by default
    assert drawn.faults.servo.bandwidth_hz == (3.0, 12.0)
    mild = trial_scene_dict(CampaignConfig(faults="mild"), 0)
    assert mild["faults"] == "mild" and scene_from_dict(mild).faults.profile == "mild"
    nominal = CampaignConfig(faults="mild", randomization=Randomization(servo="nominal"))
    assert scene_from_dict(trial_scene_dict(nominal, 0)).faults.servo is None
    plain = CampaignConfig(randomization=Randomization(servo="nominal"))
    assert "faults" not in trial_scene_dict(plain, 0)


def test_the_eval_command_parses_every_option_and_reports_without_running(tmp_path, capsys):
    from suture_bt.cli import build_parser, main
    from suture_bt.commands import eval as eval_command

    argv = ["eval", "--trials", "3", "--workers", "1", "--seed", "4", "--policy", "continue"]
    argv += ["--time-budget", "30", "--resting-fraction", "0.5", "--servo", "nominal"]
    argv += ["--rerun", "save", "--tree", "single_throw", "--out", str(tmp_path)]
    argv += ["--phantom-xy", "20", "--phantom-yaw", "15", "--phantom-tilt", "4"]
    argv += ["--brightness", "0.5", "1.8"]
    config = eval_command._config(build_parser().parse_args(argv))
    rz = config.randomization
    assert rz.brightness == (0.5, 1.8)
    assert all(0.5 <= draw(config, i)["camera"]["brightness"] <= 1.8 for i in range(20))
    assert (rz.phantom_xy_mm, rz.phantom_z_mm, rz.phantom_yaw_deg, rz.tilt_deg) == (20, 1.5, 15, 4)
    assert (config.seed, config.tree, config.policy, config.rerun) == (
        4,
        "single_throw",
        "continue",
        "save",
    )
    assert config.randomization.resting_fraction == 0.5 and config.randomization.servo == "nominal"
    assert main(["eval", "--trials", "1", "--tree", "nope", "--out", str(tmp_path)]) == 1
    assert "unknown tree 'nope'" in capsys.readouterr().err
    assert main(["eval", "--trials", "1", "--phantom-tilt", "30", "--out", str(tmp_path)]) == 1
    assert capsys.readouterr().err.strip().endswith("phantom tilt must be in [0, 15] deg, got 30.0")
    run_campaign(CampaignConfig(), 3, tmp_path, trial_fn=_fake({1: "fail"}))
    assert main(["eval", "--trials", "3", "--report-only", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "3 trials: runs passed 2/3" in out and (tmp_path / "summary.md").is_file()


def test_trials_recorded_after_the_code_changed_are_counted_in_the_report(tmp_path, monkeypatch):
    from suture_bt.campaign import campaign

    versions = iter([{"commit": "a", "modified": []}] + [{"commit": "a", "modified": []}] * 2)
    monkeypatch.setattr(campaign, "code_version", lambda: next(versions, {"commit": "b"}))
    run_campaign(CampaignConfig(), 4, tmp_path, workers=1, trial_fn=_fake())
    docs = [json.loads((trial_dir(tmp_path, i) / "trial.json").read_text()) for i in range(4)]
    changed = [d["index"] for d in docs if "code_changed" in d]
    assert len(changed) == 2 and all(
        d["code_changed"] == {"commit": "b"} for d in docs if "code_changed" in d
    )
    summary = write_report(tmp_path, 4)
    assert summary.doc["summary"]["code_changed"] == 2
    assert (
        "| trials recorded after the code changed (versions mixed: not one result) | 2 |"
        in (tmp_path / "summary.md").read_text()
    )
    # Unchanged code: nothing is flagged.
    monkeypatch.setattr(campaign, "code_version", lambda: {"commit": "a", "modified": []})
    other = tmp_path / "other"
    run_campaign(CampaignConfig(), 2, other, workers=1, trial_fn=_fake())
    assert write_report(other, 2).doc["summary"]["code_changed"] == 0
