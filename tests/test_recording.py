"""The rerun recording, read back with rerun's own reader (``rerun.chunk.RrdReader``): node
lanes, tree text, scene, images, plots and ground truth over the run's ticks; the blueprint;
the spawn fallback without a viewer; a scripted tree's failure with its reason and its
refused looks."""

import json

from recording_helpers import fake_session, looking_session, record_scripted, recorded_run
from rerun.chunk import RrdReader

from suture_bt.recording.reader import read_run


def _ranges(path):
    """entity -> (timed rows, first tick, last tick) from the raw chunks (static: 0, None)."""
    out = {}
    for chunk in RrdReader(str(path)).store().stream().to_chunks():
        rb = chunk.to_record_batch()
        ticks = rb.column("tick").to_pylist() if "tick" in rb.schema.names else []
        rows, lo, hi = out.get(chunk.entity_path.lstrip("/"), (0, None, None))
        if ticks:
            lo = min(ticks) if lo is None else min(lo, *ticks)
            hi = max(ticks) if hi is None else max(hi, *ticks)
        out[chunk.entity_path.lstrip("/")] = (rows + len(ticks), lo, hi)
    return out


def test_saved_run_has_every_kind_of_entity_over_the_right_ticks():
    out = recorded_run()
    result = json.loads((out / "result.json").read_text())
    n = result["ticks"]
    rrd = out / "run.rrd"
    ranges = _ranges(rrd)
    assert RrdReader(str(rrd)).blueprints(), "the default blueprint is stored"

    lanes = {e: r for e, r in ranges.items() if e.startswith("bt/nodes/")}
    insert = [e for e in lanes if e.endswith("/Insert_pair_1")]
    assert len(insert) == 1
    rec = read_run(rrd)
    states = [x.text for x in rec.lanes[insert[0][len("bt/nodes/") :]]]
    assert states[0] == "RUNNING" and "SUCCESS" in states
    root_lane = rec.lanes[rec.nodes[0]["path"]]
    assert root_lane[0].tick == 1 and root_lane[-1].tick == n
    assert root_lane[-1].text == result["tree_status"]
    assert ranges["bt/tree"][1] == 1 and ranges["bt/tree"][2] <= n

    # The scene: arms every 5 ticks over the whole run, ports and frames static.
    rows, first, last = ranges["world/psm1/links"]
    assert first == 1 and last > n - 5 and rows == (n + 4) // 5
    assert ranges["world/phantom/ports/entry1/square"] == (0, None, None)  # static
    assert ranges["world/needle/estimate"][0] >= 1
    assert ranges["world/plan/pair1"][0] == 1

    # Images only when perception ran (one stereo pair per localisation), with overlays.
    assert ranges["world/camera/left/image"][0] == result["localisations"]
    assert ranges["world/camera/right/image/overlay/fit"][0] >= 1
    assert ranges["world/camera/left/image/overlay/keypoints"][0] >= 1
    for arm in ("psm1", "psm2"):
        assert ranges[f"camera/calibration/{arm}"][0] == 1
        assert ranges[f"camera/calibration/{arm}/keypoints/with_dq"][0] == 1

    # Plots every tick; ground truth only under ground_truth/.
    assert ranges["plots/tracking_error/psm2"][0] == n
    assert ranges["plots/pi_output/psm1"][1:] == (1, n)
    assert ranges["ground_truth/world/needle"][1] == 1
    assert ranges["ground_truth/plots/lateral_mm/entry1"][0] >= 1
    assert ranges["ground_truth/plots/lateral_mm/exit1"][0] >= 1
    assert any(e.startswith("ground_truth/plots/strain_mm/") for e in ranges)
    outside = [e for e in ranges if "truth" in e and not e.startswith("ground_truth/")]
    assert not outside
    assert ranges["run/result"][1] == n
    assert rec.result["ticks"] == n and rec.result["passed"] == result["passed"]


def test_spawn_without_a_viewer_saves_and_says_so(tmp_path, monkeypatch):
    from suture_bt.runtime.recording import attach_recording
    from suture_bt.runtime.session import Session

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    session = Session(tree="localize", seed=0)
    said = []
    try:
        assert attach_recording(session, "off", tmp_path / "no.rrd") is None
        path = attach_recording(session, "spawn", tmp_path / "run.rrd", say=said.append)
        session.step(2)
    finally:
        session.close()
    assert path == tmp_path / "run.rrd" and not (tmp_path / "no.rrd").exists()
    assert len(said) == 1 and "cannot start a viewer here (no display" in said[0]
    rec = read_run(path)
    assert rec.tick_range == (1, 2) and rec.info["tree"] == "localize" and rec.blueprints


def test_tree_sink_logs_a_failure_with_its_reason_and_node(tmp_path):
    session = fake_session()
    record_scripted(
        session, tmp_path / "x.rrd", {"passed": False, "tree_status": "FAILURE", "ports": {}}
    )
    run = read_run(tmp_path / "x.rrd")
    assert [n["name"] for n in run.nodes] == ["Root", "Approach", "Insert pair 1"]
    assert [(e.tick, e.text) for e in run.lanes["Root/Insert_pair_1"]] == [
        (2, "RUNNING"),
        (4, "FAILURE"),
    ]
    failures = [(e.tick, e.text, e.node_path) for e in run.failures()]
    assert (4, "Insert pair 1 FAILED: jaw empty", "Root/Insert_pair_1") in failures
    assert run.result == {"passed": False, "tree_status": "FAILURE"}
    assert "Root [✕]" in run.tree_at(4).text


def test_tree_sink_logs_each_refused_look_once_with_its_node(tmp_path):
    """Each refused look once, with its node: the skill's own entry quoting its sub-skill's
    refusal is the same look and is not logged again."""
    session = looking_session()
    record_scripted(
        session, tmp_path / "x.rrd", {"passed": True, "tree_status": "SUCCESS", "ports": {}}
    )
    logged = [
        (e.tick, e.text, e.level, e.node_path)
        for e in read_run(tmp_path / "x.rrd").logs["bt/refusals"]
    ]
    path = "Root/Localize_needle"
    assert logged == [
        (1, "Localize needle: refused: needle out of view", "WARN", path),
        (3, "Localize needle: refused: valley 1.01x", "WARN", path),
        (3, "Localize needle: refused: two views disagree: 4 mm", "WARN", path),
    ]
