"""Held-out phantom poses for the needle-pose benchmark (``needle_pose.py --phantom heldout``).

Each scene draws the phantom's pose within the held-out campaigns' ranges, rebuilds the phantom
there (:meth:`~suture_bt.datagen.needle_data.SimScene.move_phantom`) and gives the localiser
that pose's tissue model, as the tree's localiser is given the task's known phantom.
"""

from __future__ import annotations

import needle_task_scenes
import numpy as np

from suture_bt.campaign.randomize import Randomization, phantom_pose_in_view
from suture_bt.datagen.needle_data import SimScene
from suture_bt.perception.needle_localizer import NeedleLocalizer
from suture_bt.perception.unseen_arc import phantom_tissue
from suture_bt.transforms import pose_to_transform

#: The held-out campaigns' phantom ranges (docs/eval/heldout_s24_summary.md), for
#: ``--phantom heldout``; the draws use their own random stream, so the scenes' other draws
#: are those of the default phantom's run.
HELDOUT_PHANTOM = Randomization(
    phantom_xy_mm=20.0, phantom_z_mm=5.0, phantom_yaw_deg=20.0, tilt_deg=5.0
)
PHANTOM_STREAM = 97
#: Phantom poses tried per scene before a task set's builder finds a reachable scene.
PHANTOM_REDRAWS = 10


def move_phantom(sim: SimScene, stream: list[int]) -> dict:
    """Draw a held-out phantom pose from ``stream`` and rebuild the phantom there; the pose (a
    scene file's ``phantom:``)."""
    pose = phantom_pose_in_view(HELDOUT_PHANTOM, np.random.default_rng(stream), sim.stereo)
    sim.move_phantom(pose_to_transform(pose["position"], pose["rpy"]))
    return pose


def tell_localizer(sim: SimScene, loc: NeedleLocalizer) -> None:
    """Give the localiser the tissue model of the phantom as it now stands."""
    loc.tissue = phantom_tissue(sim.world.task.phantom, sim.stereo.left.T_world_cam[:3, 3])


def task_scene(sim: SimScene, loc: NeedleLocalizer, cond: str, stream: list[int], phantom: str):
    """A task set's scene, its priors, the phantom pose drawn for it (None: the default
    phantom) and the scene's random generator (drawn from ``stream``; rendering goes on with
    it). A held-out phantom pose where the set's builder finds no reachable scene (its ports
    out of an arm's reach) is drawn again, up to PHANTOM_REDRAWS times, the scene's draws
    starting over; the localiser is told the pose that was kept."""
    build = needle_task_scenes.BUILDERS[cond]
    if phantom != "heldout":
        rng = np.random.default_rng(stream)
        return (*build(sim, rng), None, rng)
    for k in range(PHANTOM_REDRAWS):
        pose = move_phantom(sim, [*stream, PHANTOM_STREAM, k])
        rng = np.random.default_rng(stream)
        try:
            scene, priors = build(sim, rng)
        except RuntimeError:
            continue
        tell_localizer(sim, loc)
        return scene, priors, pose, rng
    raise RuntimeError(
        f"no reachable {cond} scene on {PHANTOM_REDRAWS} phantom poses (scene {stream[-1]})"
    )
