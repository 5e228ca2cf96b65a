"""Where in the right image the needle the left eye saw can appear: the right eye's network
window.

The needle network reads each eye at 480 px wide; the left eye must be read whole (the needle
may be anywhere), but the right eye sees the same needle within the stereo disparities of the
working range (MIN_DEPTH-MAX_DEPTH). So the right eye is read only in a window around the left
eye's coarse needle pixels, shifted through that disparity range, with a margin for the
network's context. The window sits on the network's own grid (its coarsest stride, in full
pixels) so the window's input pixels are the whole image's, and takes one of a few sizes, so
each size's frozen graph is built once (:class:`~.network.FrozenByShape`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.needle_projection import pixel_rays, project_cam

#: The network's coarsest stride (input px): the window's corners and size are multiples.
GRID_INPUT_PX = 16
#: Context (input px) kept around where the needle can appear: the network sees a jaw or a
#: shaft beside the needle through its receptive field.
MARGIN_INPUT_PX = 32
#: Window sizes (input px, height × width) the window is rounded up to; a larger need reads the
#: whole image.
SIZES_INPUT_PX = ((128, 192), (160, 256), (208, 320))


@dataclass(frozen=True)
class Window:
    """A window of the full image (full px): rows y0:y1, columns x0:x1."""

    x0: int
    y0: int
    x1: int
    y1: int


def right_window(
    left_prob: np.ndarray,
    scale: float,
    stereo: StereoCameraModel,
    depth_range: tuple[float, float],
    threshold: float,
    input_scale: float,
    image_shape: tuple[int, int],
) -> Window | None:
    """The right image's window (full px) where the left eye's coarse needle pixels
    (``left_prob`` over ``threshold``; ``scale`` full px per coarse px) can appear at depths
    in ``depth_range`` (m), grown by MARGIN_INPUT_PX and set on the network's grid for an
    input of ``input_scale`` input px per full px; None where the whole image is needed (no
    needle seen, a grid that is not whole full pixels, or no window size large enough)."""
    full_per_input = 1.0 / input_scale
    step = GRID_INPUT_PX * full_per_input
    if abs(step - round(step)) > 1e-9:
        return None
    step = int(round(step))
    ys, xs = np.nonzero(left_prob > threshold)
    if not len(xs):
        return None
    # Coarse pixel i covers full pixels i * scale - 0.5 to (i + 1) * scale - 0.5.
    u0, u1 = xs.min() * scale - 0.5, (xs.max() + 1) * scale - 0.5
    v0, v1 = ys.min() * scale - 0.5, (ys.max() + 1) * scale - 0.5
    corners = np.array([[u0, v0], [u1, v0], [u0, v1], [u1, v1]])
    rays = pixel_rays(stereo.left, corners)  # unit rays (left camera frame)
    pts = [rays * (z / rays[:, 2:3]) for z in depth_range]
    T_right_left = stereo.right.T_cam_world @ stereo.left.T_world_cam
    uv = np.concatenate(
        [project_cam(stereo.right, p @ T_right_left[:3, :3].T + T_right_left[:3, 3]) for p in pts]
    )
    margin = MARGIN_INPUT_PX * full_per_input
    lo = np.floor((uv.min(0) - margin) / step) * step
    hi = np.ceil((uv.max(0) + margin) / step) * step
    H, W = image_shape
    need_h, need_w = (hi[1] - lo[1]) * input_scale, (hi[0] - lo[0]) * input_scale
    for h, w in SIZES_INPUT_PX:
        if h >= need_h and w >= need_w:
            break
    else:
        return None
    fh, fw = int(round(h * full_per_input)), int(round(w * full_per_input))
    if fh >= H or fw >= W:
        return None
    # Centre the size on the need, then slide it inside the image (still on the grid).
    x0 = int(lo[0] - ((fw - (hi[0] - lo[0])) // (2 * step)) * step)
    y0 = int(lo[1] - ((fh - (hi[1] - lo[1])) // (2 * step)) * step)
    x_max = int(np.floor((W - fw) / step) * step)
    y_max = int(np.ceil((H - fh) / step) * step)  # the bottom may run past (padded rows)
    x0, y0 = min(max(x0, 0), x_max), min(max(y0, 0), y_max)
    return Window(x0, y0, x0 + fw, y0 + fh)
