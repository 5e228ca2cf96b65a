"""The fit's extra terms: the compiled keypoint term computes what the numpy projection of the
model's ends gives (distance from each keypoint to the nearer projected end)."""

import numpy as np
from perception_helpers import random_needle_pose, stereo

from suture_bt.geometry import NeedleModel
from suture_bt.perception.fit_terms import EndPriorTerm, _project_model_points

MODEL = NeedleModel()


def test_keypoint_term_is_the_distance_to_the_nearer_projected_end():
    st = stereo(1920, 1080)
    rng = np.random.default_rng(3)
    T = np.stack([random_needle_pose(rng, 0.03, 0.2) for _ in range(17)])
    kp = (rng.uniform(0, 1900, (3, 2)), rng.uniform(0, 1000, (2, 2)))
    term = EndPriorTerm(st, MODEL, kp)
    expected = []
    for cam, T_el, k in term.eyes:
        u, v = _project_model_points(cam, T_el, T, np.stack([MODEL.base, MODEL.tip]))
        d = np.hypot(u[:, None, :] - k[None, :, 0, None], v[:, None, :] - k[None, :, 1, None])
        expected.append(d.min(-1))
    got = term(T)
    assert got.shape == (17, 5)
    np.testing.assert_allclose(got, np.concatenate(expected, -1), rtol=0, atol=1e-9)
