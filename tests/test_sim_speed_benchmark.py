"""A tiny smoke run of benchmarks/sim_speed.py: it runs and writes every figure as JSON."""

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load():
    spec = importlib.util.spec_from_file_location("sim_speed", ROOT / "benchmarks" / "sim_speed.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_smoke_run_writes_all_figures(tmp_path, capsys, monkeypatch):
    bench = _load()
    # Small renders keep the smoke run fast; the default resolution is exercised by the benchmark.
    monkeypatch.setattr(bench, "default_scene", lambda: _small_camera_scene())
    out = tmp_path / "speed.json"
    assert bench.main(["--steps", "50", "--renders", "1", "--ik", "20", "--json", str(out)]) == 0
    figures = json.loads(out.read_text())
    assert figures["physics_steps_per_s"] > 0
    assert figures["physics_steps_per_s_needle_resting"] > 0
    assert set(figures["render_ms_per_stereo_pair"]) == {"64x48", "640x480"}
    assert all(v > 0 for v in figures["render_ms_per_stereo_pair"].values())
    assert 0 < figures["ik_us_per_solve"] < 1e5
    assert "physics_steps_per_s" in capsys.readouterr().out


def test_bad_counts_are_rejected():
    bench = _load()
    with pytest.raises(SystemExit):
        bench.main(["--steps", "0"])


def _small_camera_scene():
    from suture_bt.sim.scene import scene_from_dict

    return scene_from_dict({"camera": {"width": 64, "height": 48}})
