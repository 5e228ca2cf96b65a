"""Reading the network's output: the input is area-downsampled and padded to the network's
stride, a malformed image is a ValueError, the right eye read in a window gives the whole
image's output there and none elsewhere, keypoints on a small blob are dropped, and the
trusted ends' stereo disparity gives a depth hint only when it is plausible."""

import numpy as np
import pytest
import torch
from perception_helpers import stereo
from torch.nn import functional as F

from suture_bt.perception.network import NeedleNet
from suture_bt.perception.network_reading import (
    MIN_END_SEPARATION_PX,
    OUTSIDE_WINDOW_LOGIT,
    blob_areas,
    net_input,
    read_network,
    trusted_ends_and_depth,
)
from suture_bt.perception.stereo_window import Window


def test_net_input_keeps_the_aspect_and_pads_rows_to_a_multiple_of_16():
    small, s = net_input(np.full((1080, 1920, 3), 7, np.uint8), 480)
    assert s == 0.25 and small.shape == (272, 480, 3)
    assert (small[:270] == 7).all() and (small[270:] == 0).all()


@pytest.mark.parametrize("bad", [None, np.zeros((4, 4), np.uint8), np.zeros((0, 0, 3), np.uint8)])
def test_a_malformed_image_is_a_value_error(bad):
    net = NeedleNet(width=8).eval()
    with pytest.raises(ValueError, match="left image"):
        read_network(net, bad, np.zeros((48, 64, 3), np.uint8), 64)


def test_read_network_gives_full_resolution_keypoints_and_the_coarse_scale():
    torch.manual_seed(0)
    net = NeedleNet(width=8).eval()
    img = np.zeros((96, 128, 3), np.uint8)
    prob, kp, score, scale = read_network(net, img, img, 64)
    assert prob.shape[0] == 2 and kp.shape == (2, 2, 2) and score.shape == (2, 2)
    assert scale == pytest.approx(4.0)  # 128 px over 64, and the heads' stride of 2
    assert np.all((kp >= -0.5) & (kp <= 128))


def test_blob_areas_measure_the_blob_under_each_keypoint():
    prob = np.zeros((40, 60))
    prob[5:8, 5:8] = 0.9  # a speck: 9 coarse px
    prob[20:23, 10:40] = 0.9  # an arc-long blob: 90
    kp = np.array([[6.0, 6.0], [25.0, 21.0], [50.0, 35.0]])  # coarse px at scale 1
    np.testing.assert_array_equal(blob_areas(prob, kp, 1.0, 0.3), [9, 90, 0])


def test_trusted_ends_give_a_depth_from_their_disparity_when_it_is_plausible():
    st = stereo(1920, 1080)
    z = 0.1
    disp = st.left.fx * st.baseline / z
    left = np.array([[800.0, 500.0], [900.0, 520.0]])
    kp = np.stack([left, left - [disp, 0.0]])
    ends, depth = trusted_ends_and_depth(kp, np.full((2, 2), 0.9), st)
    np.testing.assert_array_equal(ends, left)
    assert depth == pytest.approx(z)
    # The right eye's heads swapped base and tip: matched by row, the same depth.
    swapped = np.stack([left, (left - [disp, 0.0])[::-1]])
    assert trusted_ends_and_depth(swapped, np.full((2, 2), 0.9), st)[1] == pytest.approx(z)
    # A disparity putting the needle nearer than any working distance is no hint.
    near = np.stack([left, left - [20 * disp, 0.0]])
    ends, depth = trusted_ends_and_depth(near, np.full((2, 2), 0.9), st)
    np.testing.assert_array_equal(ends, left)
    assert depth is None
    # A weak right eye: ends but no depth; a weak left keypoint or ends on one spot: neither.
    weak_right = np.array([[0.9, 0.9], [0.9, 0.05]])
    assert trusted_ends_and_depth(kp, weak_right, st)[1] is None
    assert trusted_ends_and_depth(kp, np.array([[0.9, 0.05], [0.9, 0.9]]), st) == (None, None)
    one_spot = np.stack([[left[0], left[0] + MIN_END_SEPARATION_PX / 2]] * 2)
    assert trusted_ends_and_depth(one_spot, np.full((2, 2), 0.9), st) == (None, None)


@pytest.mark.parametrize("win", [Window(640, 320, 1408, 832), Window(1152, 576, 1920, 1088)])
def test_the_right_eye_read_in_a_window_is_the_whole_images_output_there(win):
    """A local stand-in for the network (2×2 average: its output at a place sees only that
    place) shows the window's input pixels and output place are the whole image's, the
    padded bottom rows included; outside the window the right eye sees nothing."""
    rng = np.random.default_rng(3)
    left = rng.integers(0, 255, (1080, 1920, 3), dtype=np.uint8)
    right = rng.integers(0, 255, (1080, 1920, 3), dtype=np.uint8)

    def net(x):
        return F.avg_pool2d(x, 2)

    whole = read_network(net, left, right, 480)
    seen = []
    got = read_network(net, left, right, 480, lambda *a: seen.append(a) or win)
    prob_left, scale, input_scale, shape = seen[0]
    assert scale == 8.0 and input_scale == 0.25 and shape == (1080, 1920)
    np.testing.assert_array_equal(prob_left, whole[0][0])
    np.testing.assert_array_equal(got[0][0], whole[0][0])
    r0, r1, c0, c1 = win.y0 // 8, win.y1 // 8, win.x0 // 8, win.x1 // 8
    np.testing.assert_allclose(got[0][1][r0:r1, c0:c1], whole[0][1][r0:r1, c0:c1], atol=1e-6)
    outside = np.ones(got[0][1].shape, bool)
    outside[r0:r1, c0:c1] = False
    outside_p = 1.0 / (1.0 + np.exp(-OUTSIDE_WINDOW_LOGIT))
    np.testing.assert_allclose(got[0][1][outside], outside_p, rtol=1e-5)
