"""The valley probe: its starts tilt the answer about the camera's axes, its hinge term keeps
a descent away from the answer (compiled with the numpy term's arithmetic), a clean outline has
no valley near its answer, and session 48's wrong answer 78467446 ``occluded`` #34 (a held
needle answered 5.9 deg off) is refused for its valley."""

import numpy as np
import pytest
from perception_helpers import (
    MODEL,
    attempts_with_gates,
    clean_outline_args,
    lm_problem,
    pose_errors,
    recorded_fit,
)
from scipy.spatial.transform import Rotation

from suture_bt.perception import fit_solver
from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.fit_attempts import FitAttempts
from suture_bt.perception.fit_terms import AWAY_PX_PER_DEG, AwayTerm
from suture_bt.perception.lm_step import _extra_residuals, compiled_terms
from suture_bt.perception.needle_projection import params_to_pose
from suture_bt.perception.pose_fit import NeedleNotFound
from suture_bt.perception.valley_probe import (
    MAX_VALLEY_RATIO,
    VALLEY_DEG,
    VALLEY_START_DEG,
    valley_starts,
)


def _pose(rotvec, centre=(0.01, -0.005, 0.09)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = centre
    return T


def test_the_starts_tilt_the_answer_about_the_cameras_x_and_y_axes_through_its_centre():
    T = _pose([0.3, -1.1, 0.7])
    starts = valley_starts(T)
    assert starts.shape == (4, 4, 4)
    for S in starts:
        turn = Rotation.from_matrix(S[:3, :3] @ T[:3, :3].T).as_rotvec()
        assert np.degrees(np.linalg.norm(turn)) == pytest.approx(VALLEY_START_DEG)
        assert abs(turn[2]) < 1e-12  # about an axis across the line of sight
        assert np.array_equal(S[:3, 3], T[:3, 3])


def test_the_away_term_is_a_hinge_on_the_turn_from_the_answer():
    T = _pose([0.3, -1.1, 0.7])
    term = AwayTerm(T[:3, :3], VALLEY_DEG)
    turns = [0.0, 2.0, 4.9, 5.1, 30.0]
    poses = np.stack([_pose([0.0, 0.0, 0.0]) for _ in turns])
    for P, deg in zip(poses, turns, strict=True):
        P[:3, :3] = Rotation.from_rotvec(np.radians(deg) * np.array([0.6, 0.0, 0.8])).as_matrix()
        P[:3, :3] = P[:3, :3] @ T[:3, :3]
    r = term(poses)[:, 0]
    expected = [AWAY_PX_PER_DEG * max(VALLEY_DEG - d, 0.0) for d in turns]
    assert r == pytest.approx(expected, abs=1e-6)
    assert r[-2:].tolist() == [0.0, 0.0]


def test_the_compiled_away_term_gives_the_numpy_terms_residuals():
    T = _pose([0.3, -1.1, 0.7])
    term = AwayTerm(T[:3, :3], VALLEY_DEG)
    steps = np.concatenate([np.zeros((1, 6)), np.diag(fit_solver.FD_STEPS)])
    st, _, x, _ = lm_problem(cut=False)
    poses = params_to_pose(x[:, None] + steps[None], st.left, MODEL).reshape(-1, 4, 4)
    poses = np.concatenate([poses, valley_starts(T), T[None]])
    E = _extra_residuals(
        poses, compiled_terms([term], MODEL), MODEL.radius, MODEL.tip_angle, MODEL.base_angle
    )
    assert E.shape == (len(poses), 1)
    np.testing.assert_allclose(E, term(poses), rtol=0.0, atol=1e-12)
    assert E[-1, 0] == pytest.approx(AWAY_PX_PER_DEG * VALLEY_DEG)


def test_a_clean_outline_has_no_near_valley_and_is_answered():
    st, T, args = clean_outline_args()
    fit = attempts_with_gates(st)(*args)
    assert pose_errors(fit.T_cam_needle, T)[1] < 1.0
    assert fit.valley_ratio > 1.5 and fit.valley_deg >= VALLEY_DEG - 0.5
    # The gate refuses any answer at or under its limit, naming the tilted pose.
    with pytest.raises(NeedleNotFound, match="a pose tilted 5 deg from the answer"):
        attempts_with_gates(st, max_valley_ratio=fit.valley_ratio)(*args)


def test_a_fitter_that_does_not_probe_has_no_valley():
    st, _, args = clean_outline_args()
    attempts = attempts_with_gates(st)
    attempts.fitter.probe_valley = False
    fit = attempts(*args)
    assert fit.valley_ratio == float("inf") and np.isnan(fit.valley_deg)


def test_session_48s_held_needle_answered_5_9_deg_off_is_refused_for_its_valley():
    """78467446 ``occluded`` #34 as the fit saw it: a needle held 86 mm away, 70 % seen,
    answered 0.86 mm / 5.9 deg off with a predicted spread of 0.96 deg and no rival or tie;
    a pose tilted 5 deg from it costs 1.017x the answer."""
    fitter, args, kwargs, T = recorded_fit("valley_tilted_held")
    fit = fitter.fit(*args, **kwargs)
    assert pose_errors(fit.T_cam_needle, T)[1] > 5.0
    assert fit.valley_ratio == pytest.approx(1.017, abs=0.002)
    attempts = FitAttempts(fitter.stereo, fitter.model, None, fitter, AnswerGates())
    with pytest.raises(NeedleNotFound, match=r"cost 1\.01..x the answer's, limit 1\.033"):
        attempts._check(fit, ())
    # Without the valley gate every other gate passes it.
    loose = FitAttempts(fitter.stereo, fitter.model, None, fitter, AnswerGates(max_valley_ratio=0))
    loose._check(fit, ())
    assert fit.valley_ratio <= MAX_VALLEY_RATIO
