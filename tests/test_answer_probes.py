"""The answer's probes: the fitter's flags choose which run, in the documented order (the
rival probe last), and ``probed`` replaces an answer that is the needle's depth-mirror twin by
the needle (a cheaper pose, never a rival), while a right answer stays the answer."""

import numpy as np
from perception_helpers import MODEL, _scene_1080p, pose_errors, recorded_fit

from suture_bt.perception.answer_probes import (
    Finals,
    ProbeContext,
    answer_probes,
    probed,
    wide_redescent,
)
from suture_bt.perception.edge_residuals import edge_rays
from suture_bt.perception.mask_view import edge_points
from suture_bt.perception.needle_projection import params_to_pose, pose_to_params
from suture_bt.perception.pose_fit import PoseFitter
from suture_bt.perception.rival_probe import (
    MAX_TIE_RATIO,
    FitRays,
    near_starts,
    slide_starts,
    twin_starts,
)


def _kinds(probes) -> list[str]:
    names = {slide_starts: "slide", near_starts: "near"}
    out = []
    for p in probes:
        starts = getattr(p.starts, "func", p.starts)
        out.append("twin" if starts is twin_starts else names.get(starts, "rival"))
    return out


def test_the_fitters_flags_choose_the_probes_in_order_with_the_rival_probe_last():
    st, *_ = _scene_1080p(5, 0.0)
    fitter = PoseFitter(st, MODEL)
    assert _kinds(answer_probes(fitter, hidden_end=True)) == ["twin", "slide", "near", "rival"]
    assert _kinds(answer_probes(fitter, hidden_end=False)) == ["twin", "near", "rival"]
    # The twin's and the slides' costlier poses stay candidates (ties); the others' do not.
    kept = [p.keeps_costlier for p in answer_probes(fitter, hidden_end=True)]
    assert kept == [True, True, False, False]
    fitter = PoseFitter(st, MODEL, probe_twin=False, probe_rivals=False)
    assert _kinds(answer_probes(fitter, hidden_end=False)) == ["near"]


def _probed_from(T_answer, scene):
    st, T, left, right, _ = scene
    rays = edge_rays(st, edge_points(left), edge_points(right))
    fitter = PoseFitter(st, MODEL)
    xf = pose_to_params(T_answer[None], st.left, MODEL)
    cf = np.array([np.inf])  # any probe's pose is cheaper than an unrated answer
    got = probed(fitter, xf, cf, (0, None, None), FitRays(rays, rays, rays), [], [], False)
    x, cost, b, _, _, near = got
    return params_to_pose(x, st.left, MODEL), cost, b, near


def test_an_answer_that_is_the_needles_twin_is_replaced_by_the_needle():
    scene = _scene_1080p(5, 0.0)
    st, T = scene[0], scene[1]
    twin = twin_starts(T, MODEL, st.left)[0]
    poses, cost, b, near = _probed_from(twin, scene)
    pos, ang = pose_errors(poses[b], T)
    assert pos < 0.3 and ang < 1.0
    assert np.isfinite(cost[b])
    assert near[b]  # the rival probe ran from the new answer, which its rivals sit around


def test_the_wide_redescent_takes_an_answer_slid_along_its_circle_back_to_the_needle():
    st, T, left, right, _ = _scene_1080p(5, 0.0)
    rays = edge_rays(st, edge_points(left), edge_points(right))
    slid = slide_starts(T, MODEL)[1]  # 8 deg along the circle
    assert pose_errors(slid, T)[1] > 7.0
    x_slid = pose_to_params(slid[None], st.left, MODEL)[0]
    fitter = PoseFitter(st, MODEL)
    x, cost = wide_redescent(fitter, x_slid, FitRays(rays, rays, rays), [])
    pos, ang = pose_errors(params_to_pose(x, st.left, MODEL)[0], T)
    assert pos < 0.3 and ang < 1.0
    assert np.isfinite(cost[0])


def test_finals_grow_with_rivals_marked_and_the_answer_chosen_again_by_cost():
    st, *_ = _scene_1080p(5, 0.0)
    fitter = PoseFitter(st, MODEL)
    ctx = ProbeContext(fitter, [], None, [], [])
    x = np.zeros((2, 6))
    finals = Finals(x, np.array([2.0, 3.0]), 0, None, None, np.zeros(2, bool))
    finals.add(np.ones((1, 6)), np.array([1.0]), near=True)
    finals.add(np.ones((2, 6)), np.array([5.0, 4.0]), near=False)
    assert finals.near.tolist() == [False, False, True, False, False]
    assert finals.cost.tolist() == [2.0, 3.0, 1.0, 5.0, 4.0] and finals.x.shape == (5, 6)
    finals.chosen_again(ctx)  # no priors: the cheapest row
    assert finals.b == 2 and finals.misses is None
    assert len(finals.astuple()) == 6


def test_a_twin_of_near_equal_cost_stays_a_candidate_and_ties_the_answer(monkeypatch):
    """Session 39's held-out report seed 27209126, ``occluded`` #34, as the fit saw it: a needle
    101 mm away, 77 % seen, answered 14.1 mm off. Its twin with the same end pixels is the
    needle at 1.0013x the answer's cost; kept as a candidate it ties the answer (the tie gate
    refuses it), where dropped as not cheaper it left the answer without a tie."""
    fitter, args, kwargs, T = recorded_fit("near_tied_twin")
    fit = fitter.fit(*args, **kwargs)
    assert pose_errors(fit.T_cam_needle, T)[0] > 10.0
    assert 1.0 <= fit.tie_ratio < MAX_TIE_RATIO
    near = [i for i, P in enumerate(fit.candidates) if pose_errors(P, T)[0] < 2.0]
    assert near and min(fit.candidate_costs[i] for i in near) < MAX_TIE_RATIO * fit.cost
    monkeypatch.setattr("suture_bt.perception.answer_probes.TWIN_TIES", False)
    dropped = fitter.fit(*args, **kwargs)
    np.testing.assert_allclose(dropped.T_cam_needle, fit.T_cam_needle)
    assert dropped.tie_ratio > 1.2


def test_a_slide_of_near_equal_cost_stays_a_candidate_and_ties_the_answer(monkeypatch):
    """Held-out report seed 38018832, ``held_start`` #38 without priors, as the fit saw it: a
    needle held 34 mm from the eyes, 86 deg from face-on, 99 % seen, answered 11.2 deg slid
    along its own circle. The slide probe's pose 2.7 deg from the needle costs 1.0001x the
    answer; kept as a candidate it ties the answer (the tie gate refuses it), where dropped as
    not cheaper it left the answer without a tie."""
    fitter, args, kwargs, T = recorded_fit("edge_on_slide")
    swapped = MODEL.swapped(T)

    def angle_off(P):  # the fit's pose may be the base-tip swap (the localiser orients it)
        return min(pose_errors(P, T)[1], pose_errors(P, swapped)[1])

    fit = fitter.fit(*args, **kwargs)
    assert angle_off(fit.T_cam_needle) > 10.0
    assert 1.0 <= fit.tie_ratio < MAX_TIE_RATIO
    near = [i for i, P in enumerate(fit.candidates) if angle_off(P) < 5.0]
    assert near and min(fit.candidate_costs[i] for i in near) < MAX_TIE_RATIO * fit.cost
    monkeypatch.setattr("suture_bt.perception.answer_probes.SLIDE_TIES", False)
    dropped = fitter.fit(*args, **kwargs)
    np.testing.assert_allclose(dropped.T_cam_needle, fit.T_cam_needle)
    assert dropped.tie_ratio > 1.2
    assert not any(angle_off(P) < 5.0 for P in dropped.candidates)
