"""A campaign trial's resting needle start: a place on the flat tissue that both cameras see.

The SRC start pose lies below the bottom edge of this camera's image, so a campaign that wants
to measure resting starts draws its own: the needle's centre beside the ridge (clear of its
flanks), turned about the vertical at random, face up or face down, a millimetre above the
tissue (physics lets it settle), every point of its arc over the block (``EDGE_MARGIN`` from
its edges) and at least ``MARGIN_PX`` inside both images. Drawn in the phantom frame, so it
moves with the phantom. This is evaluation code: it uses the simulator's camera model to pick
scenes, never to help a tree.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from suture_bt.geometry import NeedleModel
from suture_bt.geometry.phantom import TISSUE_TOP_Z, TISSUE_X, TISSUE_Y
from suture_bt.transforms import matrix_to_rpy, pose_to_transform

#: Needle centre's distance from the ridge line x = 0 (phantom frame, m): clear of the flanks
#: (the ridge's foot is ~8 mm out, the needle's radius 10 mm) and on the block.
CENTRE_X = (0.022, 0.036)
#: Needle centre's range along the ridge (phantom frame, m).
CENTRE_Y = (-0.045, 0.045)
#: Height of the needle frame above the tissue top when it is let go (wire radius + 1 mm).
DROP_Z = 0.00136
#: Every arc point at least this far inside the tissue block's edges (m).
EDGE_MARGIN = 0.003
#: Every arc point at least this far inside both images (px).
MARGIN_PX = 40.0
TRIES = 200


def camera_of(scene_raw: dict[str, Any]) -> Any:
    """The stereo camera model of a (raw) scene's resolution."""
    from suture_bt.sim.camera import stereo_model

    camera = scene_raw.get("camera") or {}
    return stereo_model(int(camera.get("width", 1920)), int(camera.get("height", 1080)))


def in_view(camera: Any, points_world: np.ndarray, margin: float) -> bool:
    """Whether all points lie in front of both eyes and project at least ``margin`` px inside
    their images."""
    for cam in (camera.left, camera.right):
        if np.any(cam.to_camera(points_world)[:, 2] <= 0):
            return False
        uv = cam.project(points_world)
        if uv.min() < margin or np.any(uv.max(axis=0) > (cam.width - margin, cam.height - margin)):
            return False
    return True


def _on_block(points_phantom: np.ndarray) -> bool:
    """Whether every point lies over the tissue block, ``EDGE_MARGIN`` inside its edges."""
    x, y = points_phantom[:, 0], points_phantom[:, 1]
    m = EDGE_MARGIN
    return bool(
        np.all((TISSUE_X[0] + m <= x) & (x <= TISSUE_X[1] - m))
        and np.all((TISSUE_Y[0] + m <= y) & (y <= TISSUE_Y[1] - m))
    )


def resting_in_view(
    rng: np.random.Generator, T_world_phantom: np.ndarray, camera: Any
) -> dict[str, Any]:
    """A ``needle:`` scene section (``start: pose``) resting on the tissue in both views.

    Raises ``ValueError`` when no place in ``TRIES`` draws is in view (a phantom moved so far
    that its flat tissue has left the images)."""
    model = NeedleModel()
    arc = model.centerline(25)
    for _ in range(TRIES):
        side = 1.0 if rng.random() < 0.5 else -1.0
        x = side * rng.uniform(*CENTRE_X)
        y = rng.uniform(*CENTRE_Y)
        yaw = rng.uniform(-np.pi, np.pi)
        flipped = bool(rng.random() < 0.5)
        T_local = pose_to_transform(
            (x, y, TISSUE_TOP_Z + DROP_Z), (np.pi if flipped else 0.0, 0.0, yaw)
        )
        local = arc @ T_local[:3, :3].T + T_local[:3, 3]
        if not _on_block(local):
            continue
        T = T_world_phantom @ T_local
        points = arc @ T[:3, :3].T + T[:3, 3]
        if in_view(camera, points, MARGIN_PX):
            return {
                "start": "pose",
                "position": [round(float(v), 6) for v in T[:3, 3]],
                "rpy": [round(float(v), 6) for v in matrix_to_rpy(T[:3, :3])],
            }
    raise ValueError(f"no resting place on the tissue in both views after {TRIES} draws")
