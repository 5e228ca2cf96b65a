"""Held-out lighting for the needle-pose benchmark (``needle_pose.py --light heldout``).

The shipped weights' training data is lit from overhead with a camera gain of 0.7-2.0 (the
benchmark's scenes too, by default). A held-out scene may be lit otherwise: the world's harsh
lighting fault tilts the light up to 40° from overhead toward any azimuth and scales the image
by 0.4-1.6 (``sim/fault_profiles.yaml``), on top of the scene's camera brightness (0.8-1.25 in
a campaign). Each benchmark scene here draws its light's tilt from ``HELDOUT_TILT_DEG`` and its
gain from ``HELDOUT_GAIN`` (that product's range) from its own random stream, so the scene's
other draws are those of the overhead-lit run.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from suture_bt.datagen.needle_data import SceneSample
from suture_bt.sim.camera import light_direction

#: Light tilt from overhead (deg) and image gain drawn per scene.
HELDOUT_TILT_DEG = (0.0, 40.0)
HELDOUT_GAIN = (0.32, 2.0)
LIGHT_STREAM = 99


def relight(s: SceneSample, stream: list[int]) -> tuple[SceneSample, dict]:
    """The scene ``s`` under a held-out light drawn from ``stream``, and that light (a row's
    ``light``: tilt, azimuth, gain)."""
    rng = np.random.default_rng(stream)
    tilt = float(rng.uniform(*HELDOUT_TILT_DEG))
    azimuth = float(rng.uniform(0.0, 360.0))
    gain = float(rng.uniform(*HELDOUT_GAIN))
    lit = dataclasses.replace(s, brightness=gain, light_direction=light_direction(tilt, azimuth))
    return lit, {"tilt_deg": tilt, "azimuth_deg": azimuth, "gain": gain}
