"""The rival probe: its starts turn the answer as documented, ``distinct`` draws the
benchmark's line, ``rival`` picks the cheapest usable clearly different pose, and in a fit a
clean outline leaves no close rival. The slide probe's starts slide the answer along its own
circle, and from a pose slid off the needle it finds the needle. The near probe's small turns
take a Task 3 start answer stopped 5° off into the needle's own basin. A tie is measured
apart from the answer's base ↔ tip swap, which is the same outline. Probes run together give
each its own result, to the bit. The twin probe's starts keep the answer's end pixels, and
from a twin it finds the needle, an edge-on needle's flip about its chord included."""

from functools import partial

import numpy as np
import pytest
from perception_helpers import MODEL, _scene_1080p, _tip_hidden, _views, answer_index, pose_errors
from scipy.spatial.transform import Rotation

from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.edge_residuals import edge_rays
from suture_bt.perception.mask_view import edge_points
from suture_bt.perception.needle_projection import params_to_pose, pose_to_params
from suture_bt.perception.pose_fit import PoseFitter
from suture_bt.perception.rival_probe import (
    DISTINCT_DEG,
    DISTINCT_MM,
    MAX_RIVAL_RATIO,
    NEAR_ANGLES_DEG,
    OBLIQUE_MAX_DEG,
    PROBE_ANGLES_DEG,
    SLIDE_ANGLES_DEG,
    FitRays,
    RivalProbe,
    distinct,
    near_starts,
    oblique_slides,
    pose_offset,
    probe_starts,
    probe_together,
    rival,
    slide_starts,
    tie_ratio,
    twin_starts,
)


def _pose(rotvec_deg=(0.0, 0.0, 0.0), t=(0.0, 0.0, 0.1)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.deg2rad(rotvec_deg)).as_matrix()
    T[:3, 3] = t
    return T


def test_probe_starts_turn_the_answer_by_the_probe_angles_about_two_pivots():
    T = _pose((10.0, -20.0, 30.0))
    starts = probe_starts(T, MODEL)
    n_axes = 4
    assert starts.shape == (2 * n_axes * len(PROBE_ANGLES_DEG), 4, 4)
    angles = sorted({round(pose_offset(T, S)[1], 6) for S in starts})
    assert np.allclose(angles, sorted({abs(a) for a in PROBE_ANGLES_DEG}))
    # The first block turns about the arc centre: the centre stays put.
    first = starts[: len(starts) // 2]
    assert np.allclose(first[:, :3, 3], T[:3, 3])
    # The second about the arc's middle point, which stays put in every start.
    mid = 0.5 * (MODEL.base_angle + MODEL.tip_angle)
    p = MODEL.point_at(np.array([mid]))[0]
    for S in starts[len(starts) // 2 :]:
        assert np.allclose(S[:3, :3] @ p + S[:3, 3], T[:3, :3] @ p + T[:3, 3])


def test_distinct_is_the_accuracy_line():
    T = _pose()
    near = _pose((0.0, 0.8 * DISTINCT_DEG, 0.0), (0.0, 0.0, 0.1 + 0.8e-3 * DISTINCT_MM))
    turned = _pose((0.0, 1.2 * DISTINCT_DEG, 0.0))
    moved = _pose(t=(1.2e-3 * DISTINCT_MM, 0.0, 0.1))
    assert not distinct(T, near)
    assert distinct(T, turned) and distinct(T, moved)
    mm, deg = pose_offset(T, moved)
    assert np.isclose(mm, 1.2 * DISTINCT_MM) and np.isclose(deg, 0.0, atol=1e-6)


def test_rival_is_the_cheapest_usable_clearly_different_pose():
    poses = np.stack(
        [_pose(), _pose((0.0, 1.0, 0.0)), _pose((0.0, 30.0, 0.0)), _pose((0.0, 20.0, 0.0))]
    )
    costs = np.array([1.0, 0.9, 1.1, 1.05])
    usable = np.array([True, True, True, False])
    ratio, offset = rival(0, poses, costs, usable)
    # pose 1 is cheaper but the same answer; pose 3 is cheaper but unusable (a prior refuses it)
    assert np.isclose(ratio, 1.1) and np.isclose(offset[1], 30.0)
    assert rival(0, poses[:2], costs[:2], usable[:2]) == (float("inf"), None)


def _seen_at(from_face_on_deg: float, turns_deg) -> np.ndarray:
    """A pose 60 mm ahead whose plane is ``from_face_on_deg`` from face-on, then each of
    ``turns_deg`` (rotation vectors in the needle's own frame) applied to it."""
    T = _pose((from_face_on_deg, 0.0, 0.0), (0.0, 0.0, 0.06))
    turned = [T @ _pose(rv, (0.0, 0.0, 0.0)) for rv in turns_deg]
    return np.stack([T, *turned])


def test_oblique_slides_are_slides_along_the_circle_of_an_answer_seen_obliquely():
    # slid 10 and 30 deg about the needle's own z; tilted 5 deg about its x; shifted 1 mm
    turns = [(0.0, 0.0, 10.0), (0.0, 0.0, -30.0), (5.0, 0.0, 0.0)]
    poses = _seen_at(50.0, turns)
    shifted = poses[1].copy()
    shifted[0, 3] += 0.001
    poses = np.concatenate([poses, shifted[None]])
    assert oblique_slides(0, poses).tolist() == [False, True, True, False, False]
    # the slide of a slide is one too, from either
    assert oblique_slides(1, poses).tolist() == [True, False, True, False, False]
    # seen nearly edge-on, a slide moves the wire along the line of sight: it stays a rival
    edge_on = _seen_at(OBLIQUE_MAX_DEG + 10.0, turns)
    assert not oblique_slides(0, edge_on).any()
    assert oblique_slides(0, _seen_at(OBLIQUE_MAX_DEG - 1.0, turns))[1:3].all()


def test_the_swap_is_the_same_outline_with_base_and_tip_exchanged():
    T = _pose((10.0, -20.0, 30.0), (0.01, -0.02, 0.1))
    angles = np.linspace(MODEL.base_angle, MODEL.tip_angle, 9)
    arc = MODEL.point_at(angles) @ T[:3, :3].T + T[:3, 3]
    S = MODEL.swapped(T)
    arc_swapped = MODEL.point_at(angles) @ S[:3, :3].T + S[:3, 3]
    assert np.allclose(arc_swapped, arc[::-1], atol=1e-9)
    assert np.isclose(pose_offset(T, S)[1], 180.0)


def test_a_tie_ignores_the_answers_own_swap_and_unusable_poses():
    T = _pose()
    poses = np.stack([T, MODEL.swapped(T), _pose((0.0, 30.0, 0.0)), _pose((0.0, 60.0, 0.0))])
    costs = np.array([1.0, 1.0, 1.004, 0.9])
    usable = np.array([True, True, True, False])
    # pose 1 is the answer's own outline; pose 3 is cheaper but a prior refuses it
    assert np.isclose(tie_ratio(0, poses, costs, usable, MODEL), 1.004)
    assert tie_ratio(0, poses[:2], costs[:2], usable[:2], MODEL) == float("inf")


def test_a_clean_outline_leaves_no_rival_within_the_limit():
    st, T, left, right, ends = _scene_1080p(5, 2.0)
    res = PoseFitter(st, MODEL).fit(left, right, tuple(ends))
    assert res.rival_ratio > MAX_RIVAL_RATIO
    pos, ang = pose_errors(res.T_cam_needle, T)
    assert pos < 0.5 and ang < 1.5


def test_a_needle_half_hidden_has_a_turned_rival_and_the_fit_says_so(monkeypatch):
    """With the tip half hidden the seen piece stays put while the pose turns about it: the
    probe finds a pose clearly different from the answer at nearly its cost. Here that pose
    is a slide of the answer along its circle, seen 52 deg from face-on, which counts only
    where slides of an oblique answer are rivals (OBLIQUE_MAX_DEG 0); by default it does not
    (the answer's arc runs on past the seen base end, which the localiser's exposure gate
    weighs: ``test_unseen_arc``)."""
    st, T, left, right, ends = _scene_1080p(4, 0.0)
    occ, short, _ = _tip_hidden(st, T, left, right, ends)
    monkeypatch.setattr("suture_bt.perception.rival_probe.OBLIQUE_MAX_DEG", 0.0)
    res = PoseFitter(st, MODEL).fit(*occ, short)
    assert res.rival_ratio <= MAX_RIVAL_RATIO
    mm, deg = res.rival_offset
    assert mm > DISTINCT_MM or deg > DISTINCT_DEG
    free = PoseFitter(st, MODEL, probe_rivals=False).fit(*occ, short)
    assert free.rival_ratio == float("inf") and free.rival_offset is None
    monkeypatch.undo()
    oblique = PoseFitter(st, MODEL).fit(*occ, short)
    np.testing.assert_array_equal(oblique.T_cam_needle, res.T_cam_needle)
    poses = np.stack(oblique.candidates)
    b = answer_index(oblique)
    assert oblique_slides(b, poses).any()
    assert oblique.rival_ratio == float("inf")


def _slid(T: np.ndarray, deg: float) -> np.ndarray:
    S = T.copy()
    S[:3, :3] = Rotation.from_rotvec(np.deg2rad(deg) * T[:3, 2]).as_matrix() @ T[:3, :3]
    return S


def test_slide_starts_keep_the_circle_and_move_along_it():
    T = _pose((10.0, -20.0, 30.0))
    starts = slide_starts(T, MODEL)
    assert len(starts) == len(SLIDE_ANGLES_DEG)
    assert np.allclose(starts[:, :3, 3], T[:3, 3])  # the same centre
    assert np.allclose(starts[:, :3, 2], T[:3, 2])  # the same plane
    for S, a in zip(starts, SLIDE_ANGLES_DEG, strict=True):
        assert np.isclose(pose_offset(T, S)[1], abs(a))
        assert np.allclose(S, _slid(T, a))


def test_from_a_pose_slid_along_its_circle_the_slide_probe_finds_the_needle():
    st, T, left, right, _ = _scene_1080p(5, 0.0)
    rays = edge_rays(st, edge_points(left), edge_points(right))
    off = _slid(T, 10.0)
    x_off = pose_to_params(off[None], st.left, MODEL)[0]
    probe = RivalProbe(st, MODEL, n_mid=2, n_polish=1, starts=slide_starts)
    x, cost = probe(x_off, FitRays(rays, rays, rays), [], "geman_mcclure")
    assert len(x) == 1 and np.isfinite(cost[0])
    pos, ang = pose_errors(params_to_pose(x, st.left, MODEL)[0], T)
    assert pos < 0.3 and ang < 1.0


def test_twin_starts_keep_the_end_pixels_and_turn_the_arc_to_minus_psi():
    st, T, *_ = _scene_1080p(5, 0.0)
    starts = twin_starts(T, MODEL, st.left)
    x = pose_to_params(T[None], st.left, MODEL)[0]
    xs = pose_to_params(starts, st.left, MODEL)
    assert len(starts) >= 2
    assert np.allclose(xs[:, :4], x[:4], atol=1e-6)
    assert np.allclose(xs[:, 5], -x[5])
    assert all(distinct(S, T) for S in starts)


def test_from_the_depth_mirror_twin_the_twin_probe_finds_the_needle():
    """From each of a needle's twins, the probe (as the fit runs it) descends back to the
    needle. Session 27: a nearly edge-on held needle (development seed 6289076, ``occluded``
    #283) was answered as its twin, 14 mm / 146° off at 3.3× the needle's cost, because no
    start of the search fell into the needle's basin."""
    st, T, left, right, _ = _scene_1080p(5, 0.0)
    rays = edge_rays(st, edge_points(left), edge_points(right))
    twin = partial(twin_starts, cam=st.left)
    for mirror in twin_starts(T, MODEL, st.left):
        x_off = pose_to_params(mirror[None], st.left, MODEL)[0]
        probe = RivalProbe(st, MODEL, n_mid=1, n_polish=1, starts=twin)
        x, cost = probe(x_off, FitRays(rays, rays, rays), [], "geman_mcclure")
        errors = [pose_errors(P, T) for P in params_to_pose(x, st.left, MODEL)]
        assert any(pos < 0.3 and ang < 1.0 for pos, ang in errors)


def test_near_starts_turn_the_answer_a_few_degrees_about_its_centre():
    T = _pose((10.0, -20.0, 30.0))
    starts = near_starts(T, MODEL)
    assert starts.shape == (4 * len(NEAR_ANGLES_DEG), 4, 4)
    angles = sorted({round(pose_offset(T, S)[1], 6) for S in starts})
    assert np.allclose(angles, sorted({abs(a) for a in NEAR_ANGLES_DEG}))
    assert np.allclose(starts[:, :3, 3], T[:3, 3])


def test_the_near_probe_takes_a_stopped_fit_into_the_needles_basin():
    """Development scene (seed 6173, held_start #199, 39 mm from the eye, nearly edge-on):
    without priors the fit used to stop 0.93 mm / 4.95° off at 3.7x the cost of the needle's own
    pose (predicted spread 0.11°); the ±4/8° turns reach that pose. Since session 41 the mask
    holds the wire the network's mask stopped short of
    (:mod:`~suture_bt.perception.wire_growth`) and the fit finds the needle without the near
    probe; the probe's case is the record's mask."""
    from perception_helpers import task_scene

    from suture_bt.perception.needle_localizer import NeedleLocalizer

    stereo, left, right, T_true, _, tissue = task_scene("held_start", 199)
    loc = NeedleLocalizer(stereo, tissue=tissue)
    loc.fitter.probe_near = False
    whole = loc.localize(left, right)
    assert pose_errors(whole.T_cam_needle, T_true)[1] < 0.5
    loc.halve_near = False  # the record's resolution (near_view)
    loc.grow_wire = False  # the record's mask
    # Since session 19 the stopped fit is refused as exposed: that gate is off for it.
    stopped = loc.localize(left, right, gates=AnswerGates(max_exposed=float("inf")))
    loc.fitter.probe_near = True
    found = loc.localize(left, right)
    assert pose_errors(stopped.T_cam_needle, T_true)[1] > 3.0
    assert pose_errors(found.T_cam_needle, T_true)[1] < 0.5
    assert found.fit.cost < 0.5 * stopped.fit.cost


def test_probes_run_together_give_each_probe_its_own_result_to_the_bit():
    """The three probes of a fit, from two different answers in one batch, against each run
    alone (the fit runs them together and relies on this to keep its answers)."""
    st, T, left, right, _ = _scene_1080p(5, 0.0)
    rays = edge_rays(st, edge_points(left), edge_points(right))
    fit_rays = FitRays(rays, rays.subset(np.arange(0, len(rays), 8)), rays)
    small = {"n_mid": 2, "n_polish": 1}
    probes = [
        RivalProbe(st, MODEL, starts=slide_starts, **small),
        RivalProbe(st, MODEL, starts=near_starts, apart_from_answer=False, **small),
        RivalProbe(st, MODEL),
    ]
    answers = [pose_to_params(P[None], st.left, MODEL)[0] for P in (T, T, _slid(T, 10.0))]
    together = probe_together(probes, answers, fit_rays, [], "geman_mcclure")
    for probe, x_answer, (x, cost) in zip(probes, answers, together, strict=True):
        x_alone, cost_alone = probe(x_answer, fit_rays, [], "geman_mcclure")
        assert np.array_equal(x, x_alone) and np.array_equal(cost, cost_alone)
    # From the needle, slides come back to it (none kept) and the near probe keeps its best;
    # from a pose slid off it, the rival probe finds poses clearly apart, the needle's among
    # them.
    assert [len(x) for x, _ in together] == [0, 1, 2]
    found = params_to_pose(together[2][0], st.left, MODEL)
    assert min(pose_errors(P, T)[1] for P in found) < 0.5


def test_probes_with_other_cameras_or_iterations_are_not_run_together():
    st = _scene_1080p(5, 0.0)[0]
    x = pose_to_params(_pose()[None], st.left, MODEL)[0]
    probes = [RivalProbe(st, MODEL), RivalProbe(st, MODEL, iterations=(3, 3, 3))]
    with pytest.raises(ValueError, match="share their cameras, model and iterations"):
        probe_together(probes, [x, x], FitRays(None, None, None), [], "geman_mcclure")


def _edge_on(seed: int):
    """A scene whose needle is seen exactly edge-on by the left eye (psi = 90°: the arc's
    plane holds the line of sight), its masks, and its flip about its own chord (psi = -90°:
    the same ends, the arc bulging the other way in depth), which projects to the same line."""
    st, T, *_ = _scene_1080p(seed, 0.0)
    x = pose_to_params(T[None], st.left, MODEL)[0]
    T_on = params_to_pose(np.array([*x[:5], np.pi / 2]), st.left, MODEL)
    T_flip = params_to_pose(np.array([*x[:5], -np.pi / 2]), st.left, MODEL)
    left, right = _views(st, T_on)
    return st, T_on, T_flip, left, right


def test_twin_starts_of_an_edge_on_arc_hold_its_flip_about_the_chord():
    """Session 37: the twins kept only the chord's other depth roots, so an edge-on needle's
    flip about its own chord (same ends, psi → -psi) was never a start."""
    st, T_on, T_flip, *_ = _edge_on(5)
    ends = [np.stack([P[:3, :3] @ MODEL.base + P[:3, 3], P[:3, :3] @ MODEL.tip + P[:3, 3]])
            for P in (T_on, T_flip)]  # fmt: skip
    assert np.allclose(ends[0], ends[1], atol=1e-9) and distinct(T_on, T_flip)
    assert any(max(pose_offset(S, T_on)) < 1e-6 for S in twin_starts(T_flip, MODEL, st.left))


def test_from_an_edge_on_needles_flip_the_twin_probe_finds_the_needle():
    """Held-out development scene (session 36's report seed 73942248, ``occluded`` #24): a
    held needle seen 0.6° from edge-on, its middle behind the jaw, was answered as its flip
    about its chord, 17 mm / 180° off, with the needle's own pose cheaper (rms 0.21 against
    0.27 px) but never reached."""
    st, T_on, T_flip, left, right = _edge_on(5)
    rays = edge_rays(st, edge_points(left), edge_points(right))
    x_flip = pose_to_params(T_flip[None], st.left, MODEL)[0]
    probe = RivalProbe(st, MODEL, n_mid=1, n_polish=1, starts=partial(twin_starts, cam=st.left))
    x, _ = probe(x_flip, FitRays(rays, rays, rays), [], "geman_mcclure")
    errors = [pose_errors(P, T_on) for P in params_to_pose(x, st.left, MODEL)]
    assert any(pos < 0.3 and ang < 1.0 for pos, ang in errors)
