"""A near needle is measured on the images halved.

At the Task 3 start the needle is 30-48 mm from the eyes: at 1920×1080 its wire is 12-19 px
wide and its outline runs to the fit's cap of edge points in each eye, so colour refinement,
the fit and the base-or-tip choice cost a third more than for a needle at the working distance
(those calls made most of the localiser's slowest twentieth in session 47's reports). Halved,
such a needle looks as a needle twice as far does at full resolution (60-96 mm, the working
range every limit in pixels was set on), and its pose is still pinned to a few hundredths of
a millimetre. The network's output is reused (its input is the same 480-px image); only its
pixel coordinates are halved (its coarse grid then sits a quarter of a halved pixel off, far
inside the colour test's 9-px band).

Taken when the network's end keypoints put the needle nearer than :data:`HALF_RES_DEPTH` by
their stereo disparity; kept only when the halved masks' own disparity agrees
(:func:`confirms_near`), else the frame is measured again at full resolution. A refusal on the
halved images stands without priors; with the task's priors full resolution decides. On
development Task 3 starts (seeds 17239218 and, held-out phantom and light, 38018832; 30 and
40 scenes) the halved images answered 3 of 70 calls without priors that full resolution refused
and refused 2 it answered, but with priors refused 1 of 70 it answered and answered none it
refused (the coarser pixels loosen an edge-on needle: its predicted spread grows more than
twofold). Measuring every refused frame again put those frames among the slowest (a halved
call's 70-100 ms plus a full one's 100-140): the retry is kept for the calls with priors,
whose refusals are rarer and whose answers the tree waits for. No answer was wrong either way.
"""

from __future__ import annotations

import numpy as np

from suture_bt.interfaces import CameraModel, StereoCameraModel

#: Keypoint stereo depth (m) under which a frame is measured on the halved images: the nearer
#: Task 3 starts, whose wire is widest, not the 44-68 mm of the tree's presentations. At 45 mm
#: a held-out development answer with priors 44 mm away was refused halved (a rival 7° away).
HALF_RES_DEPTH = 0.038
#: The halved masks must put the needle's nearest possible depth (``NeedleMasks``' ``near``,
#: 0.85 × the nearer of the keypoints' and the masks' depths) within this (m), else the
#: keypoints were matched wrongly between the eyes and full resolution measures the frame.
HALF_RES_MAX_NEAR = 0.85 * 0.055


def wants_half(depth: float | None, shape: tuple[int, ...]) -> bool:
    """Whether a frame of image ``shape`` whose keypoints say ``depth`` (m; None: not
    measured) is measured halved: near, and of even width and height."""
    return depth is not None and depth < HALF_RES_DEPTH and shape[0] % 2 == 0 and shape[1] % 2 == 0


def confirms_near(near: float | None) -> bool:
    """Whether the halved masks' nearest possible depth (m) keeps the frame halved."""
    return near is not None and near <= HALF_RES_MAX_NEAR


def halved(rgb: np.ndarray) -> np.ndarray:
    """Every second pixel of every second row: the image a camera of half the resolution
    would take (the renderer, like a sensor's pixel, does not blend the wire into the
    tissue; an area average would, and its mixed edge pixels cost the colour test the wire's
    edges: on 30 development Task 3 starts it refused 6 of 27 answers)."""
    return np.ascontiguousarray(rgb[::2, ::2])


def halved_pixels(px: np.ndarray) -> np.ndarray:
    """Full-resolution pixel coordinates on the :func:`halved` image (pixel 2i is pixel i)."""
    return np.asarray(px, float) / 2.0


def halved_camera(cam: CameraModel) -> CameraModel:
    """The camera that takes the :func:`halved` image: focal lengths and principal point
    halved (pixel 2i of the full image is pixel i)."""
    return CameraModel(
        cam.width // 2,
        cam.height // 2,
        cam.fx / 2,
        cam.fy / 2,
        cam.cx / 2,
        cam.cy / 2,
        cam.T_world_cam,
    )


def halved_stereo(stereo: StereoCameraModel) -> StereoCameraModel:
    """Both eyes' :func:`halved_camera`."""
    return StereoCameraModel(halved_camera(stereo.left), halved_camera(stereo.right))
