"""The priors' soft term: offsets to the arc, their scale, and the information they add to the
fit's predicted spread."""

import numpy as np
import pytest
from perception_helpers import _scene_1080p, _tip_disc_hidden, random_needle_pose, stereo
from scipy.spatial.transform import Rotation

from suture_bt.geometry import NeedleModel
from suture_bt.perception.edge_residuals import edge_rays
from suture_bt.perception.fit_solver import FD_STEPS, _pose_derivatives, pose_uncertainty
from suture_bt.perception.mask_view import edge_points
from suture_bt.perception.needle_prior import (
    HeldPrior,
    PortPrior,
    PredictedPosePrior,
)
from suture_bt.perception.needle_projection import params_to_pose, pose_to_params
from suture_bt.perception.prior_term import (
    PLACE_SIGMA_SHARE,
    PRIOR_PX,
    HeldPlaceTerm,
    PriorTerm,
    prior_information,
)
from suture_bt.transforms import make_transform

MODEL = NeedleModel()


def _world(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return T[:3, :3] @ p + T[:3, 3]


def test_prior_term_counts_a_miss_of_one_tolerance_as_prior_px():
    st = stereo(640, 480)
    T_cam = random_needle_pose(np.random.default_rng(2), 0.06, 0.1)
    T_world = st.left.T_world_cam @ T_cam
    off = _world(T_world, MODEL.point_at(2.5)) + 0.002 * T_world[:3, 2]
    priors = [
        HeldPrior("psm2", off, 0.002),
        PortPrior("entry1", off, 0.004),
        PredictedPosePrior(T_world),  # not a point prior: left out
    ]
    term = PriorTerm(priors, st.left.T_cam_world, MODEL)
    assert len(term.points) == 2 and len(term.column_weights(100)) == 6
    r = term(T_cam[None]).reshape(2, 3)
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), [PRIOR_PX, PRIOR_PX / 2], rtol=1e-9)
    assert not PriorTerm([PredictedPosePrior(T_world)], st.left.T_cam_world, MODEL)
    assert not prior_information(None, T_cam, T_cam[None].repeat(6, 0), FD_STEPS).any()


def test_a_tight_prior_narrows_the_predicted_spread_of_a_loosely_seen_needle():
    st, T, left, right, ends = _scene_1080p(7, 0.0)
    hidden = [_tip_disc_hidden(v, ends, 0.9) for v in (left, right)]  # a short piece seen
    x = pose_to_params(T[None], st.left, MODEL)[0]
    rays = edge_rays(st, edge_points(hidden[0]), edge_points(hidden[1]))
    T_world = st.left.T_world_cam @ T
    # Two points of the hidden part: a port the tip passes through, a pinch nearer the middle.
    tip, mid = _world(T_world, MODEL.tip), _world(T_world, MODEL.point_at(1.6))

    def spread(tolerance: float) -> float:
        priors = [PortPrior("p", tip, tolerance), HeldPrior("a", mid, tolerance)]
        term = PriorTerm(priors, st.left.T_cam_world, MODEL)
        return pose_uncertainty(x, rays, st, MODEL, prior=term)[0]

    alone = pose_uncertainty(x, rays, st, MODEL)[0]
    assert spread(0.05) > 0.99 * alone  # a loose prior adds almost nothing
    assert spread(2e-4) < 0.5 * alone


def test_prior_information_is_the_misses_jacobian_outer_product():
    st = stereo(640, 480)
    T = random_needle_pose(np.random.default_rng(4), 0.06, 0.1)
    x = pose_to_params(T[None], st.left, MODEL)
    T0 = params_to_pose(x, st.left, MODEL)
    T6, _ = _pose_derivatives(x, T0, st.left, MODEL)
    p = _world(st.left.T_world_cam @ T, MODEL.point_at(2.0))
    term = PriorTerm([HeldPrior("psm1", p, 0.001)], st.left.T_cam_world, MODEL)
    info = prior_information(term, T0[0], T6[0], FD_STEPS)
    assert info.shape == (6, 6)
    np.testing.assert_allclose(info, info.T)
    assert np.all(np.linalg.eigvalsh(info) > -1e-9)
    # A point prior pins at most the two directions across the arc: rank ≤ 2.
    assert np.linalg.matrix_rank(info, tol=1e-6 * np.abs(info).max()) <= 2


def test_a_held_place_adds_the_slide_along_the_circle_a_point_alone_leaves_free():
    """The pinch point on the arc says nothing of where along its circle the needle sits;
    the held place does: its signed slide in standard deviations (PLACE_SIGMA_SHARE of its
    tolerance, a bound), modulo the base ↔ tip swap, and one more direction of information.
    The search's own term carries the slides alone."""
    st = stereo(640, 480)
    T = random_needle_pose(np.random.default_rng(5), 0.06, 0.1)
    T_world = st.left.T_world_cam @ T
    a = MODEL.tip_angle + 0.5
    pinch = _world(T_world, MODEL.point_at(a))
    placed = HeldPrior("psm1", pinch, 0.001, arc_angle=a, arc_tolerance=0.0005)
    term = PriorTerm([placed], st.left.T_cam_world, MODEL)
    assert len(term.column_weights(100)) == 4 and term.scaled(T[None]).shape == (1, 4)
    assert abs(term.slides(T[None])[0, 0]) < 1e-9
    turn = make_transform(Rotation.from_rotvec([0.0, 0.0, 0.05]).as_matrix(), np.zeros(3))
    slid = T @ turn
    sigma = PLACE_SIGMA_SHARE * 0.0005
    assert term.slides(slid[None])[0, 0] == pytest.approx(-0.05 * MODEL.radius / sigma)
    bound = placed.miss(st.left.T_world_cam @ slid, MODEL)  # the gate: in tolerances
    assert bound == pytest.approx(0.05 * MODEL.radius / 0.0005)
    swapped = T.copy()
    swapped[:3, :3] = T[:3, :3] @ MODEL.swap_rotation()
    assert abs(term.slides(swapped[None])[0, 0]) < 1e-9
    x = pose_to_params(T[None], st.left, MODEL)
    T0 = params_to_pose(x, st.left, MODEL)
    T6, _ = _pose_derivatives(x, T0, st.left, MODEL)
    point_only = PriorTerm([HeldPrior("psm1", pinch, 0.001)], st.left.T_cam_world, MODEL)
    rank = [
        np.linalg.matrix_rank(prior_information(t, T0[0], T6[0], FD_STEPS), tol=1e-3)
        for t in (point_only, term)
    ]
    assert rank[1] == rank[0] + 1
    search = HeldPlaceTerm([placed], st.left.T_cam_world, MODEL)
    assert not search.polish and len(search.column_weights(100)) == 1
    np.testing.assert_allclose(search(slid[None]), PRIOR_PX * term.slides(slid[None]))
    assert not HeldPlaceTerm([HeldPrior("psm1", pinch, 0.001)], st.left.T_cam_world, MODEL)
