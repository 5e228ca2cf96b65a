"""How far the needle training scenes stray from the SRC default scene: phantom pose and light.

The shipped weights' data (``suture-bt data needle``, :data:`DEFAULT_SCENE`) shows the phantom
at its default pose, lit from overhead with a gain of 0.7-2.0, while held-out scenes move, turn
and tilt the phantom and light it otherwise. ``suture-bt data needle-varied``
(:data:`VARIED_SCENES`) moves the phantom in a share of the scenes (one pose per block of
scenes: rebuilding it costs a render's time) beyond the held-out campaigns' ranges, tilts the
light as far as the harsh lighting fault does, and darkens some images below that range. Each
draw has its own random stream, so a scene's needle and arms are those it has without them.
Session 31 trained on it and did not ship the weights (README, "Reproducing the shipped
weights").
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from suture_bt.campaign.randomize import Randomization, phantom_pose_in_view
from suture_bt.sim.camera import light_direction
from suture_bt.transforms import pose_to_transform

#: Random streams (appended to a scene's or a block's seed sequence).
PHANTOM_STREAM, LIGHT_STREAM = 201, 202


@dataclass(frozen=True)
class SceneVariety:
    """Shares and ranges of the phantom-pose and lighting variations in the training data."""

    #: Phantom pose ranges: wider than the held-out campaigns' (±20 mm, ±5 mm, ±20°, ±5°).
    phantom: Randomization = Randomization(
        phantom_xy_mm=25.0, phantom_z_mm=6.0, phantom_yaw_deg=25.0, tilt_deg=7.0
    )
    #: Share of scene blocks with the phantom moved, and scenes per block.
    phantom_share: float = 0.6
    phantom_block: int = 10
    #: Share of scenes lit from a tilted light, and its tilt range (deg) from overhead.
    light_share: float = 0.5
    light_tilt_deg: tuple[float, float] = (0.0, 40.0)
    #: Share of scenes darkened below the sampler's 0.7-2.0 gain, and that gain's range.
    dark_share: float = 0.2
    dark_gain: tuple[float, float] = (0.3, 0.7)

    def phantom_pose(self, seed: int, block: int, camera) -> np.ndarray | None:
        """The phantom's world pose for scene block ``block`` (None: the default pose)."""
        rng = np.random.default_rng([seed, block, PHANTOM_STREAM])
        if rng.random() >= self.phantom_share:
            return None
        pose = phantom_pose_in_view(self.phantom, rng, camera)
        return pose_to_transform(pose["position"], pose["rpy"])

    def light(self, s, seed: int, scene: int):
        """Scene sample ``s`` with this scene's light direction and gain drawn."""
        rng = np.random.default_rng([seed, scene, LIGHT_STREAM])
        tilted, dark = rng.random() < self.light_share, rng.random() < self.dark_share
        tilt, azimuth = rng.uniform(*self.light_tilt_deg), rng.uniform(0.0, 360.0)
        gain = rng.uniform(*self.dark_gain)
        return dataclasses.replace(
            s,
            light_direction=light_direction(tilt, azimuth) if tilted else s.light_direction,
            brightness=float(gain) if dark else s.brightness,
        )


#: Phantom poses and lights varied (``suture-bt data needle-varied``).
VARIED_SCENES = SceneVariety()
#: The SRC default scene only: the shipped weights' data (``suture-bt data needle``).
DEFAULT_SCENE = SceneVariety(phantom_share=0.0, light_share=0.0, dark_share=0.0)
