"""Tip trajectory recorder: the true needle tip at a fixed simulated rate, written as CSV."""

import csv

import numpy as np
import pytest

from suture_bt.evaluation import TipRecorder
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World


@pytest.fixture
def world():
    scene = scene_from_dict({"needle": {"start": "in_psm2_jaw"}, "servo": {"error_model": False}})
    with World.from_scene(scene, with_camera=False) as w:
        yield w


def test_records_the_moving_tip_at_its_rate_and_writes_csv(world, tmp_path):
    truth = GroundTruth(world)
    tip0 = truth.needle_tip()
    rec = TipRecorder(world, rate_hz=100)
    reference = {}  # the exact tip at the end of every tick, stamped with that tick's time
    world.add_periodic(0.001, lambda t: reference.update({round(t - 0.001, 6): truth.needle_tip()}))
    world.psm2.move_jp(world.psm2.setpoint_jp() + np.array([0.05, 0.03, 0.0, 0.2, 0.1, 0.1]))
    world.step(1.0)
    rows = rec.rows
    assert len(rows) >= 100  # ≥ 100 rows per simulated second
    t = np.array([r[0] for r in rows])
    assert np.allclose(np.diff(t), 0.01) and t[0] == 0.0 and t[-1] < 1.0
    assert np.allclose(rows[0][1:], tip0)  # the first row is the start state
    for row in rows[1:]:
        assert np.allclose(row[1:], reference[round(row[0], 6)], atol=1e-9)
    xyz = rec.as_array()[:, 1:]
    assert np.linalg.norm(xyz[-1] - xyz[0]) > 0.005  # it followed the arm
    path = rec.write_csv(tmp_path / "out" / "tip.csv")
    with path.open() as f:
        table = list(csv.reader(f))
    assert table[0] == ["t", "tip_x", "tip_y", "tip_z"]
    data = np.array(table[1:], dtype=float)
    assert data.shape == (len(rows), 4)
    assert np.allclose(data, rec.as_array(), atol=1e-6)
    rec.detach()
    rec.detach()  # idempotent
    world.step(0.1)
    assert len(rec.rows) == len(rows)


def test_exact_tip_of_a_held_needle_and_invalid_rates(world):
    truth = GroundTruth(world)
    world.psm2.move_jp(world.psm2.setpoint_jp() + np.array([0.05, 0.03, 0.0, 0.2, 0.1, 0.1]))
    world.step(0.2)  # ends on a bookkeeping update: the body sits exactly on its jaw
    assert np.allclose(truth.needle_tip(), truth.needle_scored_points()["tip"], atol=1e-6)
    with pytest.raises(ValueError):
        TipRecorder(world, rate_hz=300)  # not a whole number of 1 kHz ticks
    with pytest.raises(ValueError):
        TipRecorder(world, rate_hz=0)
