"""What a refused look says about an uncalibrated arm's hidden offset.

Before calibration an arm's tip may be anywhere the task's offset bound allows: presentations
keep the held needle clear of the tissue under every offset of the bound. When an eye then
sees nothing of a needle at all, the offsets that would have put the whole needle well inside
that image are ruled out: the jaw's pinch point must lie outside the image or within the
needle's reach (its diameter, in pixels at its depth, plus ``BORDER_PX``) of its border. The
offsets left decide the next presentation, which can then stand where the needle shows.
When an eye does see needle (an answer the checks refused, or a needle cut by the image
border), the offsets under which that needle could not be in the jaw are ruled out: the seen
pixels must lie near the places a needle held across the jaws can be (its circle on either side
of the pinch point), projected from the tip pose the offset gives.
Known kinematics, the camera model and the network's mask only; no ground truth.
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
#: Seen needle pixels must lie this near a place the held needle can be (px, plus the
#: needle plane's tilt from across the jaws, ``SEEN_TILT_DEG``, at its depth): the coarse
#: mask's cells are 16 px and it spills a cell past the wire.
SEEN_NEAR_PX = 32.0
SEEN_TILT_DEG = 10.0
#: Share of the seen pixels that must be near (a stray cell on the jaw may not be).
SEEN_SHARE = 0.9
#: Fewest seen pixels in an eye for that eye to count.
MIN_SEEN = 4
#: Samples of each of the two circles the held needle may lie on.
SEEN_SAMPLES = 48


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


def held_circles(T_tip: np.ndarray, radius: float, samples: int = SEEN_SAMPLES) -> np.ndarray:
    """World points of the two circles a needle held across the jaws at ``T_tip`` lies on:
    through the pinch point, in the tip's x-y plane, centred one radius along ±tip y."""
    pinch = T_tip[:3, 3] - GRASP_DEPTH * T_tip[:3, 2]
    a = np.linspace(0.0, 2 * np.pi, samples, endpoint=False)
    ring = radius * (np.cos(a)[:, None] * T_tip[:3, 0] + np.sin(a)[:, None] * T_tip[:3, 1])
    return np.vstack([pinch + s * radius * T_tip[:3, 1] + ring for s in (1.0, -1.0)])


def seen_offsets(
    ctx: TaskContext,
    arm: ArmHandle,
    q_look: np.ndarray,
    seen: tuple[np.ndarray, np.ndarray],
    offsets: np.ndarray,
) -> np.ndarray:
    """The rows of ``offsets`` under which the needle pixels ``seen`` (left, right; N×2 each)
    in a look at joints ``q_look`` can be the needle held by ``arm``: ``SEEN_SHARE`` of each
    eye's pixels near the projection of :func:`held_circles` at the tip that offset gives."""
    cams = (ctx.camera.model.left, ctx.camera.model.right)
    eyes = [
        (c, np.asarray(px, float)) for c, px in zip(cams, seen, strict=True) if len(px) >= MIN_SEEN
    ]
    if not eyes:
        return offsets
    base = arm.base_frame()
    r = ctx.needle.radius
    tilt_m = 2.0 * r * np.sin(np.deg2rad(SEEN_TILT_DEG))
    keep = np.ones(len(offsets), bool)
    for i, dq in enumerate(offsets):
        q = np.array(q_look, dtype=float)
        q[:3] += dq
        circles = held_circles(base @ forward_kinematics(q), r)
        for cam, px in eyes:
            z = cam.to_camera(circles)[:, 2]
            if np.any(z <= 0.0):
                break  # behind the camera: this eye bounds nothing
            uv = cam.project(circles)
            near = SEEN_NEAR_PX + tilt_m * cam.fx / float(np.min(z))
            d = np.min(np.linalg.norm(px[:, None, :] - uv[None], axis=2), axis=1)
            if np.quantile(d, SEEN_SHARE) > near:
                keep[i] = False
                break
    return offsets[keep]
