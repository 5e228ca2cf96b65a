"""The fit stage: end hypotheses compared without order, the answer's gates refuse with their
reasons, and a clean outline is answered."""

import numpy as np
import pytest
from perception_helpers import pose_errors
from test_pose_fit import MODEL, _scene_1080p, _tip_hidden

from suture_bt.perception.colour_refine import ColourRule
from suture_bt.perception.fit_attempts import (
    MAX_RIVAL_RATIO,
    MAX_TIE_RATIO,
    FitAttempts,
    _same_pair,
)
from suture_bt.perception.pose_fit import NeedleNotFound, PoseFitter


def test_end_pairs_match_in_either_order_within_tolerance():
    a = (np.array([10.0, 10.0]), np.array([50.0, 20.0]))
    assert _same_pair(a, (a[1] + 1.0, a[0] - 1.0))
    assert not _same_pair(a, (a[1], a[0] + 5.0))


def _attempts(st, **kw) -> FitAttempts:
    return FitAttempts(st, MODEL, ColourRule(), PoseFitter(st, MODEL), **kw)


def _args(seed: int = 7):
    """A 1080p needle's exact masks on black images, its true end pixels as keypoints."""
    st, T, left, right, ends = _scene_1080p(seed, 0.0)
    images = tuple(np.zeros((1080, 1920, 3), np.uint8) for _ in range(2))
    kp = np.stack([ends, ends])
    score = np.full((2, 2), 0.9)
    return st, T, (images, (left, right), tuple(ends), None, 2.0, None, kp, score)


def test_a_clean_outline_is_answered_and_each_gate_refuses_with_its_reason():
    st, T, args = _args()
    fit = _attempts(st)(*args)
    pos, ang = pose_errors(fit.T_cam_needle, T)
    assert pos < 0.5 and ang < 1.0
    with pytest.raises(NeedleNotFound, match="RMS"):
        _attempts(st, max_rms_px=0.0)(*args)
    with pytest.raises(NeedleNotFound, match="leaves the pose loose"):
        _attempts(st, max_angle_std_deg=0.0)(*args)
    with pytest.raises(NeedleNotFound, match="leaves the needle's position loose"):
        _attempts(st, max_position_std_mm=0.0)(*args)


def test_an_answer_with_a_close_rival_is_refused_with_its_reason():
    """Half the needle hidden: a turned pose explains the seen piece as well (see
    test_rival_probe), so the answer is refused, naming the rival's offset and cost."""
    st, T, left, right, ends = _scene_1080p(4, 0.0)
    occ, short, _ = _tip_hidden(st, T, left, right, ends)
    images = tuple(np.zeros((1080, 1920, 3), np.uint8) for _ in range(2))
    args = (images, tuple(occ), short, None, 2.0, None, np.stack([short, short]), np.zeros((2, 2)))
    loose = dict(max_angle_std_deg=float("inf"))
    with pytest.raises(NeedleNotFound, match="another pose .* explains the outline almost as well"):
        _attempts(st, **loose)(*args)
    # The rival ties the answer: without the rival gate the tie gate refuses it.
    with pytest.raises(NeedleNotFound, match="explain the outline equally well"):
        _attempts(st, max_rival_ratio=0.0, **loose)(*args)
    fit = _attempts(st, max_rival_ratio=0.0, max_tie_ratio=0.0, **loose)(*args)
    assert fit.rival_ratio <= MAX_RIVAL_RATIO and fit.tie_ratio <= MAX_TIE_RATIO
