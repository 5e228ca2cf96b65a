"""SRC throw scoring on plain records (no simulator), and on a real world's ground truth."""

import json
import subprocess
import sys
from dataclasses import dataclass, field

import numpy as np
import pytest

from suture_bt.evaluation import (
    ThrowScore,
    records_from_world,
    run_passed,
    score_throws,
    src_sequence,
    task3_order_ok,
)


@dataclass
class X:
    """A stand-in for the phantom's Crossing record."""

    port: str
    t: float
    lateral: float = 0.0
    tip_out: float = 0.0
    inward: bool | None = None
    point: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        self.kind = self.port.rstrip("0123456789")
        self.pair = int(self.port[len(self.kind) :])
        if self.inward is None:  # the SRC direction by default
            self.inward = self.kind == "entry"

    @property
    def src_direction(self) -> bool:
        return self.inward if self.kind == "entry" else not self.inward


@dataclass
class E:
    """A stand-in for the phantom's TissueEntry record."""

    t: float
    nearest_port: str
    distance: float
    point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    depth_max: float = 0.005


@dataclass
class S:
    circle: float
    plane: float = 0.0


def good_throw(pair: int, t0: float) -> tuple[list[X], list[E]]:
    """A clean throw of ``pair`` starting at t0: entry at 0.3 mm, exit at 0.4 mm, 6 mm out."""
    xs = [X(f"entry{pair}", t0 + 1.0, 3e-4), X(f"exit{pair}", t0 + 2.0, 4e-4, tip_out=6e-3)]
    return xs, [E(t0 + 1.0, f"entry{pair}", 3e-4)]


def four_throws():
    crossings, entries, windows = [], [], {}
    for i in (1, 2, 3, 4):
        xs, es = good_throw(i, 10.0 * i)
        crossings += xs
        entries += es
        windows[i] = (10.0 * i, 10.0 * i + 5.0)
    return crossings, entries, windows


def test_four_clean_throws_pass_in_order():
    crossings, entries, windows = four_throws()
    strain = {"entry2": S(2e-4), "exit2": S(7e-4)}
    scores = score_throws(crossings, entries, strain, windows)
    assert [s.pair for s in scores] == [1, 2, 3, 4]
    assert all(s.passed and s.failure is None for s in scores), [s.failure for s in scores]
    assert run_passed(scores) and task3_order_ok(crossings)
    s = scores[1]
    assert s.entry_lateral_mm == pytest.approx(0.3) and s.exit_lateral_mm == pytest.approx(0.4)
    assert s.tip_out_mm == pytest.approx(6.0) and s.sim_time_s == pytest.approx(5.0)
    # Strain over 0.5 mm is reported, not failed.
    assert s.strain_mm == pytest.approx(0.7) and s.strain_high and s.passed
    assert scores[0].strain_mm is None and not scores[0].strain_high
    assert s.stab_mm is None
    d = s.to_dict()
    assert json.loads(json.dumps(d)) == d
    assert d["entry_lateral_mm"] == 0.3 and d["stab_mm"] is None and d["strain_high"] is True
    assert set(d) == set(ThrowScore.__dataclass_fields__) | {"strain_high"}


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        (lambda xs, es: xs.pop(0), "no entry crossing of entry1"),
        (lambda xs, es: xs.pop(1), "no exit crossing of exit1 after entry1"),
        (lambda xs, es: setattr(xs[1], "t", 0.5), "exit1 crossed before entry1"),
        (lambda xs, es: setattr(xs[1], "lateral", 3.1e-3), "exit lateral 3.1 mm > 2.5 mm"),
        (lambda xs, es: setattr(xs[0], "lateral", 2.6e-3), "entry lateral 2.6 mm > 2.5 mm"),
        (lambda xs, es: setattr(xs[1], "tip_out", 4.2e-3), "tip out 4.2 mm < 5 mm"),
        (lambda xs, es: setattr(xs[0], "inward", False), "no entry crossing of entry1"),
        (lambda xs, es: es.append(E(0.5, "entry2", 1e-3)), "stab 1.0 mm from entry2 (nearest"),
        (lambda xs, es: es.append(E(0.5, "entry1", 12e-3)), "stab 12.0 mm from entry1"),
    ],
)
def test_each_rule_fails_the_throw_with_its_reason(change, reason):
    xs, es = good_throw(1, 0.0)
    change(xs, es)
    (score,) = score_throws(xs, es, {}, {1: (0.0, 5.0)}, pairs=(1,))
    assert not score.passed and not run_passed([score])
    assert reason in score.failure, score.failure
    assert "\n" not in score.failure


def test_boundaries_and_retries():
    xs, es = good_throw(1, 0.0)
    xs[0].lateral, xs[1].lateral, xs[1].tip_out = 2.5e-3, 2.5e-3, 5e-3  # exactly at the limits
    es.append(E(0.9, "entry1", 2.4e-3))  # a second touch at the port is no stab
    assert score_throws(xs, es, {}, {1: (0.0, 5.0)}, pairs=(1,))[0].passed
    # A first try that misses laterally, backs out, and a retry at the port: the retry counts.
    xs, es = good_throw(1, 0.0)
    xs[:0] = [X("entry1", 0.2, 3.5e-3), X("entry1", 0.4, 3.5e-3, inward=False)]
    (s,) = score_throws(xs, es, {}, {1: (0.0, 5.0)}, pairs=(1,))
    assert s.passed and s.entry_lateral_mm == pytest.approx(0.3)
    assert src_sequence(xs) == ["entry1", "exit1"] and task3_order_ok(xs, pairs=(1,))


def test_windows_and_attempts():
    crossings, entries, windows = four_throws()
    windows[3] = None
    del windows[4]
    entries = [e for e in entries if e.nearest_port in ("entry1", "entry2")]
    scores = score_throws(crossings, entries, {}, windows)
    assert [s.passed for s in scores] == [True, True, False, False]
    assert [s.failure for s in scores[2:]] == ["not attempted", "not attempted"]
    assert scores[3].to_dict()["sim_time_s"] is None and not run_passed(scores)
    assert not run_passed([])
    # Crossings outside a throw's window do not count for it.
    (s,) = score_throws(crossings, entries, {}, {1: (13.0, 15.0)}, pairs=(1,))
    assert s.failure.startswith("no entry crossing of entry1; ")  # (later entries: stabs)
    assert "after the throw" in s.failure


def test_tissue_entered_outside_every_throw_is_charged_to_the_throw_that_follows():
    crossings, entries, windows = four_throws()
    preparing = E(2.0, "entry2", 3.4e-3)  # dragged through the tissue while preparing
    between = E(26.0, "exit2", 1e-3)  # between throws 2 and 3 (window 3 starts at 30)
    after = E(60.0, "exit4", 0.5e-3)  # after the last throw ended (45)
    for extra, charged in ((preparing, 1), (between, 3), (after, 4)):
        scores = score_throws(crossings, [*entries, extra], {}, windows)
        failed = [s.pair for s in scores if not s.passed]
        assert failed == [charged], (extra, failed)
        word = "after" if extra is after else "before"
        assert f"{word} the throw" in scores[charged - 1].failure
    # At the throw's own entry port, before its window: not a stab.
    early = E(29.0, "entry3", 1e-3)
    assert all(s.passed for s in score_throws(crossings, [*entries, early], {}, windows))


def test_stab_distance_is_from_the_throws_own_entry_port_when_ports_are_known():
    xs, es = good_throw(2, 0.0)
    ports = {"entry2": np.array([0.0, 0.0, 0.0]), "entry1": np.array([0.0, 0.02, 0.0])}
    es.append(E(0.5, "entry1", 1e-3, point=np.array([0.0, 0.019, 0.0])))  # near entry1
    (s,) = score_throws(xs, es, {}, {2: (0.0, 5.0)}, pairs=(2,), port_positions=ports)
    assert s.stab_mm == pytest.approx(19.0) and "stab 19.0 mm from entry2" in s.failure


def test_a_needle_resting_on_the_tissue_is_contact_not_a_stab():
    xs, es = good_throw(1, 10.0)
    resting = E(2.0, "entry2", 0.04, depth_max=0.1e-3)  # laid down, pressed in 0.1 mm
    (s,) = score_throws(xs, [*es, resting], {}, {1: (10.0, 15.0)}, pairs=(1,))
    assert s.passed and s.stab_mm is None
    pricked = E(2.0, "entry2", 0.04, depth_max=0.8e-3)  # the tip went in deeper: a stab
    (s,) = score_throws(xs, [*es, pricked], {}, {1: (10.0, 15.0)}, pairs=(1,))
    assert not s.passed and "stab 40.0 mm from entry2 (nearest port)" in s.failure


def test_task3_order():
    crossings, _, _ = four_throws()
    assert task3_order_ok(crossings)
    swapped = [*crossings[2:4], *crossings[:2], *crossings[4:]]
    for k, c in enumerate(swapped):
        c.t = float(k)
    assert not task3_order_ok(swapped)
    crossings, _, _ = four_throws()
    assert not task3_order_ok(crossings[:-1])  # Exit4 missing
    extra = [*crossings, X("entry1", 100.0)]
    assert not task3_order_ok(extra)
    back_out = [*crossings, X("entry4", 100.0, inward=False)]  # not an SRC-direction crossing
    assert task3_order_ok(back_out)


def test_scoring_imports_no_simulator():
    code = (
        "import sys, suture_bt.evaluation.throw_scores, suture_bt.evaluation; "
        "assert 'pybullet' not in sys.modules and 'suture_bt.sim' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_records_from_a_world_score_a_scripted_throw():
    """A held needle pushed into the flat tissue in a throw's window is a stab of that throw."""
    from suture_bt.sim.ground_truth import GroundTruth
    from suture_bt.sim.scene import scene_from_dict
    from suture_bt.sim.world import World
    from suture_bt.transforms import invert

    scene = scene_from_dict({"needle": {"start": "in_psm2_jaw"}, "servo": {"error_model": False}})
    with World.from_scene(scene, with_camera=False) as w:
        truth = GroundTruth(w)
        goal = truth.tip_pose_world("psm2")
        goal[2, 3] -= 0.028
        w.psm2.move_cp(invert(w.psm2.base_frame()) @ goal)
        w.step(1.0)
        records = records_from_world(truth)
        assert len(records.tissue_entries) == 1 and records.crossings == []
        assert set(records.port_positions) == {
            f"{k}{i}" for k in ("entry", "exit") for i in (1, 2, 3, 4)
        }
        scores = records.score({1: (0.0, 1.0)}, pairs=(1, 2))
        e = records.tissue_entries[0]
        expected = np.linalg.norm(e.point - records.port_positions["entry1"]) * 1e3
        assert scores[0].stab_mm == pytest.approx(expected) and expected > 2.5
        assert scores[0].failure.startswith("no entry crossing of entry1; stab ")
        assert scores[1].failure == "not attempted"
