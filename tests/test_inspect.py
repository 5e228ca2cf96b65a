"""``suture-bt inspect`` and ``replay``: a saved run as text with no viewer; a scripted
failure with its reason and tick; refused looks; bad input as one line and a non-zero exit."""

from recording_helpers import fake_session, looking_session, record_scripted, recorded_run

from suture_bt.cli import main


def _inspect(capsys, *args):
    code = main(["inspect", *map(str, args)])
    return code, capsys.readouterr()


def test_inspect_a_saved_run(capsys):
    rrd = recorded_run() / "run.rrd"
    code, out = _inspect(capsys, rrd)
    text = out.out
    assert code == 0, out.err
    assert "run: tree single_throw, seed 0" in text and "blueprint stored" in text
    assert "ticks: 1.." in text and "result: " in text and "pair 1:" in text
    assert "Insert pair 1" in text and "Calibrate PSM1" in text
    assert "failures (" in text and "failed checks (" in text

    code, out = _inspect(capsys, rrd, "--node", "Insert pair 1")
    assert code == 0 and "RUNNING" in out.out and "[INFO] Insert pair 1 started" in out.out
    code, out = _inspect(capsys, rrd, "--tree-at", 1)
    assert code == 0 and "tree at tick 1 (logged tick 1" in out.out and "[*]" in out.out
    code, out = _inspect(capsys, rrd, "--entities")
    assert code == 0 and "world/psm1/links" in out.out and "ground_truth/world/needle" in out.out


def test_inspect_shows_each_failure_with_its_reason_and_tick(tmp_path, capsys):
    session = fake_session()
    record_scripted(session, tmp_path / "x.rrd")
    code, out = _inspect(capsys, tmp_path / "x.rrd")
    assert code == 0
    assert "ticks: 1..4" in out.out
    assert "tick 4 (0.06 s) Insert pair 1 FAILED: jaw empty  [Root/Insert_pair_1]" in out.out
    assert "result: none recorded" in out.out


def test_inspect_lists_refused_looks_with_their_reasons(tmp_path, capsys):
    session = looking_session()
    record_scripted(session, tmp_path / "x.rrd")
    code, out = _inspect(capsys, tmp_path / "x.rrd")
    assert code == 0 and "refused looks (3):" in out.out
    assert "tick 1 (0.00 s) Localize needle: refused: needle out of view" in out.out
    code, out = _inspect(capsys, tmp_path / "x.rrd", "--node", "Localize needle")
    assert code == 0 and "[WARN] Localize needle: refused: valley 1.01x" in out.out


def test_bad_recordings_are_one_line_and_nonzero(tmp_path, capsys, monkeypatch):
    junk = tmp_path / "junk.rrd"
    junk.write_bytes(b"not a recording at all")
    for command, path, fragment in [
        ("inspect", tmp_path / "none.rrd", "none.rrd: no such file"),
        ("inspect", junk, "not a readable rerun recording"),
        ("replay", tmp_path / "none.rrd", "no such file"),
    ]:
        assert main([command, str(path)]) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and fragment in err[0], err
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["replay", str(recorded_run() / "run.rrd")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot open a viewer here: no display" in err[0]
    assert "suture-bt inspect" in err[0]
