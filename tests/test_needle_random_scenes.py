"""The benchmark's random scenes meet their visibility condition: an unoccluded needle is seen
almost whole, an occluded one 40-90 % behind an arm placed between it and the camera."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import needle_random_scenes  # noqa: E402

from suture_bt.datagen.needle_data import SimScene  # noqa: E402
from suture_bt.kinematics import forward_kinematics  # noqa: E402
from suture_bt.transforms import invert  # noqa: E402


@pytest.fixture(scope="module")
def sim():
    s = SimScene(320, 240)
    yield s
    s.close()


@pytest.mark.parametrize(("cond", "lo", "hi"), [("unoccluded", 0.97, 1.0), ("occluded", 0.4, 0.9)])
def test_a_drawn_scene_meets_its_visible_share(sim, cond, lo, hi):
    rng = np.random.default_rng(3)
    s, left, frac, draws = needle_random_scenes.draw_scene(sim, cond, rng, 0)
    assert lo <= frac <= hi and draws >= 1
    assert left.shape == (240, 320, 3)


def test_the_occluding_arm_tip_lies_between_camera_and_needle(sim):
    rng = np.random.default_rng(5)
    s = sim.sampler.sample(rng, scenario="free", zr=(0.08, 0.2))
    got = needle_random_scenes.occluding_arm(sim, s, rng)
    assert got is not None
    _, arm, q = got
    tip = (sim.sampler.bases[arm] @ forward_kinematics(q))[:3, 3]
    z_tip = sim.stereo.left.to_camera(tip[None])[0, 2]
    z_needle = (invert(sim.stereo.left.T_world_cam) @ s.T_world_needle)[2, 3]
    assert 0.03 < z_tip < z_needle
