"""Points against the needle's arc: offsets to its nearest point, and the compiled loop
against a plain numpy form."""

import numpy as np
from perception_helpers import random_needle_pose

from suture_bt.geometry import NeedleModel
from suture_bt.perception.arc_geometry import arc_distance, arc_offsets
from suture_bt.perception.needle_prior import HeldPrior
from suture_bt.perception.prior_term import PriorTerm

MODEL = NeedleModel()


def _world(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return T[:3, :3] @ p + T[:3, 3]


def test_arc_offsets_are_zero_on_the_arc_and_measure_the_miss_off_it():
    T = random_needle_pose(np.random.default_rng(1), 0.05, 0.1)
    on = _world(T, MODEL.point_at(2.0))
    # 1 mm off the arc along the needle's normal, and 2 mm beyond the tip along the chord.
    off = on + 0.001 * T[:3, 2]
    d = arc_offsets(T[None], np.stack([on, off]), MODEL)[0]
    assert np.linalg.norm(d[0]) < 1e-12
    assert np.isclose(np.linalg.norm(d[1]), 0.001)
    np.testing.assert_allclose(d[1], -0.001 * T[:3, 2], atol=1e-12)  # from the point to the arc
    past_tip = np.array([np.sin(MODEL.tip_angle), -np.cos(MODEL.tip_angle), 0.0])
    beyond = _world(T, MODEL.tip + 0.002 * past_tip)
    assert np.isclose(np.linalg.norm(arc_offsets(T[None], beyond[None], MODEL)[0, 0]), 0.002)
    # Just past the base (arc angle π, so its angle wraps to -π + ε): the base is nearest, not
    # the tip a clamp of the wrapped angle would give; arc_distance is the same measure.
    past_base = _world(T, MODEL.base + 0.002 * np.array([0.0, -1.0, 0.0]))
    d = arc_offsets(T[None], past_base[None], MODEL)[0, 0]
    np.testing.assert_allclose(_world(T, MODEL.base) - past_base, d, atol=1e-12)
    assert np.isclose(arc_distance(past_base, T, MODEL), 0.002)


def _numpy_arc_offsets(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The nearest-arc-point offsets written as plain numpy (the reference of the compiled
    loop): the point into each needle frame, its angle clamped to the circle within the span,
    else the nearer end, the offset back in the pose's frame."""
    R, t = T[:, :3, :3], T[:, :3, 3]
    p = np.einsum("kji,kpj->kpi", R, points[None] - t[:, None])
    theta = np.arctan2(p[..., 1], p[..., 0])
    on_circle = MODEL.radius * np.stack([np.cos(theta), np.sin(theta), 0 * theta], -1)
    ends = np.stack([MODEL.tip, MODEL.base])
    end = ends[np.argmin(np.linalg.norm(p[..., None, :] - ends, axis=-1), -1)]
    inside = (theta >= MODEL.tip_angle) & (theta <= MODEL.base_angle)
    return np.einsum("kij,kpj->kpi", R, np.where(inside[..., None], on_circle, end) - p)


def test_the_compiled_offsets_equal_the_numpy_reference():
    """:func:`arc_offsets` (compiled) and PriorTerm's misses equal the numpy reference for
    points on, off, and past either end of the arc, over many poses."""
    rng = np.random.default_rng(4)
    T = np.stack([random_needle_pose(rng, 0.03, 0.2) for _ in range(9)])
    centre = T[0, :3, 3]
    points = centre + rng.normal(0.0, 0.012, (40, 3))
    reference = _numpy_arc_offsets(T, points)
    np.testing.assert_allclose(arc_offsets(T, points, MODEL), reference, atol=1e-15)
    priors = [HeldPrior("psm1", p, 0.002) for p in points]
    term = PriorTerm(priors, np.eye(4), MODEL)
    np.testing.assert_allclose(term.misses(T) * 0.002, reference, atol=1e-15)
