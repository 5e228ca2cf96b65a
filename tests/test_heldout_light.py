"""Held-out lighting for the needle benchmark: drawn within its ranges, reproducible, and the
render really is lit from the drawn direction."""

import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import heldout_light  # noqa: E402

from suture_bt.datagen.needle_data import SimScene  # noqa: E402
from suture_bt.sim.camera import light_direction  # noqa: E402


def test_relight_draws_within_range_from_its_stream_and_keeps_the_scene():
    sim = SimScene(320, 240)
    try:
        s = sim.sampler.sample(np.random.default_rng(4))
        lit, light = heldout_light.relight(s, [7, 0, 3, heldout_light.LIGHT_STREAM])
        again, light2 = heldout_light.relight(s, [7, 0, 3, heldout_light.LIGHT_STREAM])
        other, light3 = heldout_light.relight(s, [7, 0, 4, heldout_light.LIGHT_STREAM])
        assert light == light2 and light != light3
        lo, hi = heldout_light.HELDOUT_GAIN
        assert lo <= light["gain"] <= hi and lit.brightness == light["gain"]
        assert 0.0 <= light["tilt_deg"] <= heldout_light.HELDOUT_TILT_DEG[1]
        assert np.isclose(np.degrees(np.arccos(lit.light_direction[2])), light["tilt_deg"])
        assert lit.scenario == s.scenario and np.array_equal(lit.T_world_needle, s.T_world_needle)
        assert lit.noise_std == s.noise_std and s.light_direction is None

        # The render follows the drawn direction: tilting the light changes the image.
        quiet = dataclasses.replace(s, noise_std=0.0, brightness=1.0)
        tilted = dataclasses.replace(quiet, light_direction=light_direction(30, 0))
        sim.apply(quiet)
        rng = np.random.default_rng(0)
        overhead, mask = sim.render("left", quiet, rng)
        side, mask2 = sim.render("left", tilted, rng)
        assert np.array_equal(mask, mask2)
        assert np.abs(overhead.astype(int) - side.astype(int)).mean() > 1.0
    finally:
        sim.close()
