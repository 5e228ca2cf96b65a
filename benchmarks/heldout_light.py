"""Held-out lighting for the needle-pose benchmark (``needle_pose.py --light heldout``).

The localiser's training data is lit from overhead with a camera gain of 0.7-2.0. A held-out
scene may be lit otherwise: the world's lighting fault tilts the light up to 30° from overhead
toward any azimuth and scales the image by 0.6-1.4 (``sim.fault_config.LightingSpec``), on top
of the scene's camera brightness (0.8-1.25 in a campaign). Each benchmark scene here draws its
light direction from that range and its gain from ``HELDOUT_GAIN``, their product's range
(darker than any training image), from its own random stream, so the scene's other draws are
those of the overhead-lit run.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from suture_bt.datagen.needle_data import SceneSample

#: Light tilt from overhead (deg) and image gain drawn per scene.
HELDOUT_TILT_DEG = (0.0, 30.0)
HELDOUT_GAIN = (0.45, 1.8)
LIGHT_STREAM = 99


def light_direction(tilt_deg: float, azimuth_deg: float) -> tuple[float, float, float]:
    """Unit direction towards a light tilted ``tilt_deg`` from overhead toward ``azimuth_deg``
    (world frame; as the world's lighting fault draws it)."""
    t, a = math.radians(tilt_deg), math.radians(azimuth_deg)
    return (math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t))


def relight(s: SceneSample, stream: list[int]) -> tuple[SceneSample, dict]:
    """The scene ``s`` under a held-out light drawn from ``stream``, and that light (a row's
    ``light``: tilt, azimuth, gain)."""
    rng = np.random.default_rng(stream)
    tilt = float(rng.uniform(*HELDOUT_TILT_DEG))
    azimuth = float(rng.uniform(0.0, 360.0))
    gain = float(rng.uniform(*HELDOUT_GAIN))
    lit = dataclasses.replace(s, brightness=gain, light_direction=light_direction(tilt, azimuth))
    return lit, {"tilt_deg": tilt, "azimuth_deg": azimuth, "gain": gain}
