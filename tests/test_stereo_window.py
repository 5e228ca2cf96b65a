"""The right eye's network window: it holds every place the left eye's needle pixels can
appear in the right image over the working range, sits on the network's grid at one of its
few sizes, and is None where the whole image must be read."""

import numpy as np
import pytest
from perception_helpers import random_needle_pose, stereo

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_masks import MAX_DEPTH, MIN_DEPTH
from suture_bt.perception.needle_projection import project_cam, transform_points
from suture_bt.perception.stereo_window import (
    GRID_INPUT_PX,
    MARGIN_INPUT_PX,
    SIZES_INPUT_PX,
    right_window,
)
from suture_bt.transforms import invert

MODEL = NeedleModel()
SCALE = 8.0  # full px per coarse px at 1920 wide: input 480 (×4), heads at stride 2
INPUT_SCALE = 0.25


def _coarse_prob(uv: np.ndarray, shape=(136, 240)) -> np.ndarray:
    prob = np.zeros(shape)
    ij = np.round((uv + 0.5) / SCALE - 0.5).astype(int)
    prob[ij[:, 1], ij[:, 0]] = 0.9
    return prob


@pytest.mark.parametrize("depth", [0.025, 0.06, 0.19])
def test_the_window_holds_the_needle_in_the_right_eye_at_any_working_depth(depth):
    st = stereo(1920, 1080)
    rng = np.random.default_rng(int(depth * 1e3))
    T = random_needle_pose(rng, depth, depth)
    pts = MODEL.centerline(64)
    uv_left = project_cam(st.left, transform_points(T, pts))
    T_right = invert(st.right.T_world_cam) @ st.left.T_world_cam @ T
    uv_right = project_cam(st.right, transform_points(T_right, pts))
    w = right_window(
        _coarse_prob(uv_left), SCALE, st, (MIN_DEPTH, MAX_DEPTH), 0.5, INPUT_SCALE, (1080, 1920)
    )
    assert w is not None
    m = MARGIN_INPUT_PX / INPUT_SCALE - SCALE  # the context margin, less a coarse pixel
    (u0, v0), (u1, v1) = uv_right.min(0), uv_right.max(0)
    assert u0 - w.x0 >= m or (w.x0 == 0 and u0 > 0)
    assert w.x1 - u1 >= m or (w.x1 == 1920 and u1 < 1920)
    assert v0 - w.y0 >= m or (w.y0 == 0 and v0 > 0)
    assert w.y1 - v1 >= m or (w.y1 == 1088 and v1 < 1080)
    step = GRID_INPUT_PX / INPUT_SCALE
    assert w.x0 % step == 0 and w.y0 % step == 0
    size = (round((w.y1 - w.y0) * INPUT_SCALE), round((w.x1 - w.x0) * INPUT_SCALE))
    assert size in SIZES_INPUT_PX
    assert 0 <= w.x0 and w.x1 <= 1920 and 0 <= w.y0 and w.y1 <= 1088  # 1080 rows, padded


def test_nothing_seen_or_a_grid_off_whole_pixels_or_a_wide_need_reads_the_whole_image():
    st = stereo(1920, 1080)
    depths = (MIN_DEPTH, MAX_DEPTH)
    assert right_window(np.zeros((136, 240)), SCALE, st, depths, 0.5, 0.25, (1080, 1920)) is None
    prob = np.zeros((136, 240))
    prob[60:64, 100:110] = 0.9
    assert right_window(prob, SCALE, st, depths, 0.5, 0.25, (1080, 1920)) is not None
    # 1280 px read at 480: 42.7 full px per grid step, not whole pixels.
    st2 = stereo(1280, 720)
    assert right_window(prob, 1280 / 240, st2, depths, 0.5, 480 / 1280, (720, 1280)) is None
    prob[10:120, 20:220] = 0.9  # seen all over the image: no window is large enough
    assert right_window(prob, SCALE, st, depths, 0.5, 0.25, (1080, 1920)) is None
