"""What a refused look says about an uncalibrated arm's hidden offset.

Before calibration an arm's tip may be anywhere the task's offset bound allows: presentations
keep the held needle clear of the tissue under every offset of the bound. When an eye then
sees nothing of a needle at all, the offsets that would have put the whole needle well inside
that image are ruled out: the jaw's pinch point must lie outside the image or within the
needle's reach (its diameter, in pixels at its depth, plus ``BORDER_PX``) of its border. The
offsets left decide the next presentation, which can then stand where the needle shows.
Known kinematics, the camera model and the refusal only; no ground truth.
"""

from __future__ import annotations

import numpy as np

from suture_bt.calibration.calibration_pose import offset_box_points
from suture_bt.kinematics import forward_kinematics
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.grasps import GRASP_DEPTH

#: Grid levels per joint over the offset bound (levels³ offsets).
LEVELS = 5
#: Pixels added to the needle's reach from the border (a sliver the network may miss).
BORDER_PX = 40


def offset_grid() -> np.ndarray:
    """Offsets (N×3: rad, rad, m) over the task's bound: where nothing is known yet."""
    return offset_box_points(LEVELS)


def unseen_offsets(
    ctx: TaskContext, arm: ArmHandle, q_look: np.ndarray, eye: str, offsets: np.ndarray
) -> np.ndarray:
    """The rows of ``offsets`` that agree with a look at joints ``q_look`` in which ``eye``
    ("left" or "right") saw nothing of the needle held by ``arm``."""
    cam = ctx.camera.model.left if eye == "left" else ctx.camera.model.right
    base = arm.base_frame()
    reach_m = 2.0 * ctx.needle.radius
    keep = np.zeros(len(offsets), bool)
    for i, dq in enumerate(offsets):
        q = np.array(q_look, dtype=float)
        q[:3] += dq
        T = base @ forward_kinematics(q)
        pinch = T[:3, 3] - GRASP_DEPTH * T[:3, 2]
        depth = float(cam.to_camera(pinch[None])[0][2])
        if depth <= 0.0:
            keep[i] = True
            continue
        u, v = cam.project(pinch[None])[0]
        r = reach_m * cam.fx / depth + BORDER_PX
        keep[i] = not (r <= u <= cam.width - r and r <= v <= cam.height - r)
    return offsets[keep]
