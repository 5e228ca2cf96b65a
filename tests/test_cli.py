"""The suture-bt CLI: scene summary and images; bad input is one line on stderr, non-zero exit."""

import subprocess
import sys

import pytest

from suture_bt.cli import main


def _run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "suture_bt.cli", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["scene", "--scene", "/no/such/scene.yaml"], "no such file"),
        (["frobnicate"], "invalid choice"),
        (["scene", "--zoom", "3"], "unrecognized arguments"),
        ([], "a command is required"),
        (["scene", "--out", "/proc/no-such-dir/out"], "No such file or directory"),
    ],
)
def test_bad_input_one_line_nonzero_exit(args, fragment):
    proc = _run(*args)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert fragment in lines[0]
    assert "Traceback" not in proc.stderr


def test_malformed_and_invalid_scene_files(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera: {width: [1,\n")
    assert main(["scene", "--scene", str(bad)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not valid YAML" in err[0]
    bad.write_text("camera:\n  width: abc\n")
    assert main(["run", "--scene", str(bad)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["suture-bt: error: scene.camera.width: expected a positive integer, got 'abc'"]


def test_scene_prints_summary(tmp_path, capsys):
    scene = tmp_path / "s.yaml"
    scene.write_text("arms:\n  psm2:\n    joint_offset: B\ncamera:\n  width: 64\n  height: 48\n")
    assert main(["scene", "--scene", str(scene), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "psm1   (+100.0, +134.6, +135.0)" in out
    assert "entry1 (-3.74, +44.19, +75.00)" in out
    assert "[GROUND TRUTH]" in out
    assert "psm2   (+2.52, -0.46, +4.00)" in out


def test_run_rejects_an_unknown_tree_in_one_line(tmp_path, capsys):
    assert main(["run", "no_such_tree", "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown tree 'no_such_tree'" in err[0] and "multi_throw" in err[0]


def test_run_rejects_a_malformed_scene_in_one_line(tmp_path, capsys):
    scene = tmp_path / "s.yaml"
    scene.write_text("camera:\n  width: abc\n")
    assert main(["run", "--scene", str(scene), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene.camera.width" in err[0]


def test_run_with_missing_weights_ends_in_one_line(tmp_path, capsys, monkeypatch):
    import suture_bt.perception.network as network

    monkeypatch.setattr(network, "DEFAULT_WEIGHTS", tmp_path / "gone" / "needle_net.pt")
    assert main(["run", "localize", "--out", str(tmp_path / "out"), "--rerun", "off"]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "needle_net.pt" in err[0], err
    assert "Traceback" not in captured.err + captured.out
