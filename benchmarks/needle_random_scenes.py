"""The needle benchmark's random scenes (``unoccluded``, ``occluded``): a needle resting on the
tissue, free in view, held in a jaw or partly in a port, 80-200 mm from the cameras where the
scene allows it, with the share of its pixels the left eye sees (≥ 97 %, or 40-90 % behind an
arm placed in the way).
"""

from __future__ import annotations

import numpy as np

from suture_bt.datagen.needle_data import SimScene
from suture_bt.kinematics import forward_kinematics
from suture_bt.perception.needle_projection import rasterize_needle
from suture_bt.transforms import invert

#: Scene mix: SRC Task 1's needle resting on the tissue, a needle free in view, held in
#: either jaw, or partly inserted in a port.
SCEN_NAMES = ("resting", "free", "held_psm1", "held_psm2", "in_port")
SCEN_WEIGHTS = (0.3, 0.3, 0.15, 0.15, 0.1)
#: Draws per benchmark scene until one meets its condition (visible share of the needle).
MAX_SCENE_ATTEMPTS = 200


def visible_fraction(sim: SimScene, s, mask: np.ndarray) -> float:
    """Share of the needle's whole silhouette in the left eye that ``mask`` (what is seen)
    holds."""
    T = invert(sim.stereo.left.T_world_cam) @ s.T_world_needle
    full = rasterize_needle(sim.stereo.left, T, sim.model)
    return float((mask & full).sum() / max(full.sum(), 1))


def occluding_arm(sim: SimScene, s, rng, tries: int = 300):
    """Joints for an arm whose tip lies between the camera and the needle (image-near)."""
    cam = sim.stereo.left
    T_cn = invert(cam.T_world_cam) @ s.T_world_needle
    target = cam.project(s.T_world_needle[:3, 3][None])[0]
    best = None
    for _ in range(tries):
        arm = ("psm1", "psm2")[int(rng.integers(2))]
        if s.scenario == f"held_{arm}":
            continue
        q = rng.uniform([-1.2, -0.9, 0.08, -2.5, -1.3, -1.3], [1.2, 0.9, 0.22, 2.5, 1.3, 1.3])
        tip = (sim.sampler.bases[arm] @ forward_kinematics(q))[:3, 3]
        pc = cam.to_camera(tip[None])[0]
        if not (0.03 < pc[2] < T_cn[2, 3] - 0.005):
            continue
        d = np.linalg.norm(cam.project(tip[None])[0] - target)
        if best is None or d < best[0]:
            best = (d, arm, q)
    return best


def draw_scene(sim: SimScene, cond: str, rng, i: int):
    """A scene meeting ``cond`` (visible needle share): (sample, left image, share, draws)."""
    for draws in range(1, MAX_SCENE_ATTEMPTS + 1):
        scen = str(rng.choice(list(SCEN_NAMES), p=list(SCEN_WEIGHTS)))
        s = sim.sampler.sample(rng, scenario=scen, zr=(0.08, 0.2))
        if cond == "unoccluded":
            for a in ("psm1", "psm2"):
                if s.scenario != f"held_{a}":
                    s.q[a] = sim.sampler._arm_q(a, rng, False)
        else:
            occ = occluding_arm(sim, s, rng)
            if occ is None:
                continue
            s.q[occ[1]] = occ[2]
        sim.apply(s)
        left, mask = sim.render("left", s, rng)
        frac = visible_fraction(sim, s, mask)
        if (cond == "unoccluded" and frac >= 0.97) or (cond == "occluded" and 0.4 <= frac <= 0.9):
            return s, left, frac, draws
    raise RuntimeError(f"no {cond} scene in {MAX_SCENE_ATTEMPTS} draws (scene {i})")
