"""What the needle network says about a stereo frame: coarse needle masks, end keypoints, which
keypoints to trust, and a depth hint from their stereo disparity (the localiser's first step).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

from suture_bt.interfaces import StereoCameraModel
from suture_bt.perception.near_view import halved_pixels
from suture_bt.perception.needle_masks import MAX_DEPTH, MIN_DEPTH
from suture_bt.perception.network import OUTPUT_STRIDE, decode_ends, to_input

#: A keypoint heatmap peak below this probability is not trusted (the mask's ends are used).
MIN_KEYPOINT_SCORE = 0.15
#: Slack on how far apart one needle's two end keypoints can be (its chord seen at MIN_DEPTH).
MAX_CHORD_MARGIN = 1.2
#: Base and tip keypoints closer than this (full-resolution px) are not trusted as two ends.
MIN_END_SEPARATION_PX = 8.0


@dataclass(frozen=True)
class NetworkOutput:
    """:func:`read_network`'s reading of a frame: coarse probabilities (2, h, w), keypoints
    (2 eyes, 2 ends, 2) in the images' px, their scores (2, 2), image px per coarse px."""

    prob: np.ndarray
    keypoints: np.ndarray
    scores: np.ndarray
    scale: float

    def halved(self) -> NetworkOutput:
        """The same reading on the images halved (:mod:`near_view`)."""
        return NetworkOutput(self.prob, halved_pixels(self.keypoints), self.scores, self.scale / 2)


def net_input(rgb: np.ndarray, width: int) -> tuple[np.ndarray, float]:
    """Area-downsample to ``width`` (aspect kept), pad rows to a multiple of 16; scale."""
    H, W = rgb.shape[:2]
    s = width / W
    h = int(round(H * s))
    small = cv2.resize(rgb, (width, h), interpolation=cv2.INTER_AREA)
    hp = int(np.ceil(h / 16) * 16)
    if hp != h:
        small = np.concatenate([small, np.zeros((hp - h, width, 3), small.dtype)], 0)
    return small, s


def read_network(net, left: np.ndarray, right: np.ndarray, width: int, right_window=None):
    """Coarse mask probabilities (2, h, w), keypoints (2 eyes, 2 ends, 2) in full-resolution
    px, their scores (2, 2), and full px per coarse px; ValueError for a malformed image.

    ``right_window`` (optional: left coarse probabilities, full px per coarse px, input px per
    full px, image shape → a :class:`~.stereo_window.Window` or None) reads the right eye only
    in that window (:mod:`~.stereo_window`); outside it the right eye sees no needle."""
    for name, img in (("left", left), ("right", right)):
        if img is None or img.ndim != 3 or img.shape[2] != 3 or img.size == 0:
            shape = None if img is None else img.shape
            raise ValueError(f"{name} image must be H×W×3 RGB, got {shape}")
    a, s = net_input(left, width)
    with torch.inference_mode():
        # One eye at a time: the same outputs as one batch of both (bitwise), faster on a CPU
        # (one eye's activations stay in cache: 28 against 36 ms).
        out_left = net(_tensor(a))
        win = None
        if right_window is not None:
            prob_left = torch.sigmoid(out_left[0, 0]).numpy()
            win = right_window(prob_left, OUTPUT_STRIDE / s, s, left.shape[:2])
        if win is None:
            out_right = net(_tensor(net_input(right, width)[0]))
        else:
            out_right = _read_window(net, right, s, win, out_left.shape)
        out = torch.cat([out_left, out_right])
    # Over both eyes at once, as before the window: the same bits as the answers measured.
    prob = torch.sigmoid(out[:, 0]).numpy()
    kp, score = decode_ends(out[:, 1], out[:, 2])
    kp_full = ((kp + 0.5) * OUTPUT_STRIDE) / s - 0.5
    return prob, kp_full, score, OUTPUT_STRIDE / s


#: Logit of the right eye's outputs outside its window (probability about 1e-13).
OUTSIDE_WINDOW_LOGIT = -30.0


def _tensor(img: np.ndarray) -> torch.Tensor:
    """The network's input tensor (1, 3, H, W) for an RGB image, in channels-last memory."""
    return to_input(img).contiguous(memory_format=torch.channels_last)


def _read_window(net, img: np.ndarray, s: float, win, shape) -> torch.Tensor:
    """The network's output for ``img`` read only in ``win`` (full px, on the network's grid),
    set into an output of ``shape`` that is OUTSIDE_WINDOW_LOGIT elsewhere."""
    crop = img[win.y0 : min(win.y1, img.shape[0]), win.x0 : win.x1]
    # At the bottom the window runs past the image: net_input pads it as it pads the whole.
    small, _ = net_input(crop, int(round((win.x1 - win.x0) * s)))
    got = net(_tensor(small))
    out = torch.full(shape, OUTSIDE_WINDOW_LOGIT, dtype=got.dtype)
    r0, c0 = int(round(win.y0 * s / OUTPUT_STRIDE)), int(round(win.x0 * s / OUTPUT_STRIDE))
    rows = min(got.shape[2], shape[2] - r0)
    out[:, :, r0 : r0 + rows, c0 : c0 + got.shape[3]] = got[:, :, :rows]
    return out


def plausible_scores(
    kp: np.ndarray,
    score: np.ndarray,
    max_apart_px: float,
    prob: np.ndarray | None = None,
    scale: float = 1.0,
    coarse_threshold: float = 0.3,
) -> np.ndarray:
    """Scores with one keypoint of an eye zeroed when the two are farther apart than
    ``max_apart_px`` (the needle's chord at the nearest working distance): one of them then
    sits on something else, e.g. a jaw tip, and would pick the wrong blob as the needle. The
    one dropped lies on the smaller blob of the coarse mask ``prob`` (``scale``: full px per
    coarse px) — a jaw tip is a speck beside the needle's arc — or, on a tie or without
    ``prob``, is the weaker (development in_port #16 of seed 1000: the stronger, 0.41 against
    0.17, sat on the other arm's jaw tip)."""
    out = score.copy()
    for eye in (0, 1):
        if out[eye].min() >= MIN_KEYPOINT_SCORE:
            if np.linalg.norm(kp[eye, 0] - kp[eye, 1]) > max_apart_px:
                areas = (
                    None
                    if prob is None
                    else blob_areas(prob[eye], kp[eye], scale, coarse_threshold)
                )
                if areas is None or areas[0] == areas[1]:
                    out[eye, int(np.argmin(out[eye]))] = 0.0
                else:
                    out[eye, int(np.argmin(areas))] = 0.0
    return out


def blob_areas(prob: np.ndarray, kp: np.ndarray, scale: float, threshold: float) -> np.ndarray:
    """Area (coarse px) of the coarse mask's blob (``prob`` over ``threshold``) each keypoint
    (2, 2; full px) lies on (0: on none)."""
    m = (prob > threshold).astype(np.uint8)
    _, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    out = np.zeros(len(kp))
    h, w = lab.shape
    for i, (u, v) in enumerate((np.asarray(kp, float) + 0.5) / scale - 0.5):
        x, y = int(round(u)), int(round(v))
        win = lab[max(y - 2, 0) : min(y + 3, h), max(x - 2, 0) : min(x + 3, w)]
        labels = win[win > 0]
        if len(labels):
            out[i] = stats[labels, cv2.CC_STAT_AREA].max()
    return out


def trusted_ends_and_depth(kp: np.ndarray, score: np.ndarray, stereo: StereoCameraModel):
    """Left (base, tip) pixels when trusted, and a depth hint from their disparity.

    The needle's two ends look alike, so the heads may both fire on one end (then the fit
    finds the ends from the mask) or swap between the eyes (pairs are matched by row).
    """
    if score[0].min() < MIN_KEYPOINT_SCORE:
        return None, None
    if np.linalg.norm(kp[0, 0] - kp[0, 1]) < MIN_END_SEPARATION_PX:
        return None, None
    ends, depth = (kp[0, 0], kp[0, 1]), None
    if score[1].min() >= MIN_KEYPOINT_SCORE:
        right = kp[1]
        if np.abs(kp[0, :, 1] - right[::-1, 1]).sum() < np.abs(kp[0, :, 1] - right[:, 1]).sum():
            right = right[::-1]
        disp = kp[0, :, 0] - right[:, 0]
        if np.all(disp > 1.0):
            depth = float(np.mean(stereo.left.fx * stereo.baseline / disp))
            if not MIN_DEPTH <= depth <= MAX_DEPTH:
                depth = None  # implausible disparity (ends mismatched between the eyes)
    return ends, depth
