"""The unseen part of a fitted needle must be hidden by something (issue 14 item 4)."""

import numpy as np
from perception_helpers import (
    GREY,
    MODEL,
    PINK,
    _scene_1080p,
    face_on_scene,
    images_with_cover,
    pose_errors,
    recorded_fit,
    twin_case,
)

from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.fit_attempts import FitAttempts
from suture_bt.perception.pose_fit import NeedleNotFound
from suture_bt.perception.unseen_arc import (
    EXPOSED,
    HIDDEN,
    SEEN,
    arc_exposure,
    below_port_planes,
    hiders,
)

HW = 2.0  # the wire's half width at 80 mm, 640×480 (px, rounded up)


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def test_the_true_pose_is_seen_everywhere():
    st, T, imgs, views = face_on_scene()
    e = arc_exposure(imgs, views, st, T, MODEL, HW)
    assert all((c == SEEN).all() for c in e.classes) and e.worst == 0.0


def test_a_pose_turned_within_its_plane_runs_over_background():
    """A slide along the circle: the circle right, its ends 7 mm along it off the needle."""
    st, T, imgs, views = face_on_scene()
    turned = T.copy()
    turned[:3, :3] = _rz(0.7)
    e = arc_exposure(imgs, views, st, turned, MODEL, HW)
    assert e.both > 0.004 and min(e.end_exposed) > 0.004


def test_a_jaw_in_front_hides_the_unseen_part():
    st, T, imgs, views = face_on_scene(occluder=True)
    e = arc_exposure(imgs, views, st, T, MODEL, HW)
    assert e.both == 0.0 and (e.classes[0] == HIDDEN).sum() > 10


def test_specks_of_grey_in_the_tissue_hide_nothing():
    """Dim tissue's sensor noise passes the colour test in specks (90509673 `held_presented`
    #1, light gain 0.33): a slid pose over them is still exposed; the jaw still hides."""
    st, T, imgs, views = face_on_scene(background=PINK)
    rng = np.random.default_rng(5)
    speckled = []
    for img in imgs:
        img = img.copy()
        ys, xs = rng.integers(0, img.shape[0], 3000), rng.integers(0, img.shape[1], 3000)
        img[ys, xs] = GREY  # about 1 % of the pixels, single ones
        speckled.append(img)
    turned = T.copy()
    turned[:3, :3] = _rz(0.7)
    e = arc_exposure(tuple(speckled), views, st, turned, MODEL, HW)
    assert e.both > 0.004 and min(e.end_exposed) > 0.004
    st, T, imgs, views = face_on_scene(occluder=True, background=PINK)
    e = arc_exposure(imgs, views, st, T, MODEL, HW)
    assert e.both == 0.0 and (e.classes[0] == HIDDEN).sum() > 10


def test_hiders_drop_specks_but_keep_blobs_and_what_the_window_cuts():
    grey = np.zeros((60, 60), bool)
    grey[10, 10] = grey[30, 31] = True  # specks
    grey[20:40, 40:50] = True  # a jaw's blade
    grey[0:2, 20:23] = True  # a small piece cut by the window's top edge
    out = hiders(grey, 2.0)  # a wire 4 px wide: blobs under 16 px² are specks
    assert not out[10, 10] and not out[30, 31]
    assert out[20:40, 40:50].all() and out[0:2, 20:23].all()
    assert out.sum() == 200 + 6


def test_tissue_hides_only_where_the_needle_may_be_inside_it():
    st, T, imgs, views = face_on_scene(background=PINK)
    turned = T.copy()
    turned[:3, :3] = _rz(0.7)
    assert arc_exposure(imgs, views, st, turned, MODEL, HW).both > 0.004
    assert arc_exposure(imgs, views, st, turned, MODEL, HW, tissue_hides=True).both == 0.0
    # A port 1 mm nearer, its outward normal toward the camera: the needle is under its plane.
    T_world = st.left.T_world_cam @ turned
    port = T_world[:3, 3] - 0.001 * st.left.T_world_cam[:3, 2]
    normal = -st.left.T_world_cam[:3, 2]
    inside = below_port_planes([(port, normal)])
    e = arc_exposure(imgs, views, st, turned, MODEL, HW, inside_tissue=inside)
    assert e.both == 0.0
    assert (EXPOSED not in e.classes[0]) and (SEEN in e.classes[0])


def test_the_mirror_twin_of_a_needle_behind_a_jaw_runs_over_background(monkeypatch):
    """test_needle_prior's twin case: the tip half behind a jaw (grey, just over the hidden
    wire), the fit without priors answers the tilt-mirror twin > 10 mm off: the needle's
    unseen part is under the jaw, the twin's lies over the black background."""
    from suture_bt.perception.exposure_gate import MAX_EXPOSED
    from suture_bt.perception.pose_fit import PoseFitter

    st, T, occ, short, kw = twin_case(monkeypatch)
    _, _, left, right, _ = _scene_1080p(10, 0.0)
    imgs = images_with_cover(st, (left, right), occ, px=2)
    # The twin the fit answers without its rival probe (with it, the fit moves to a cheaper
    # twin 18 mm / 132 deg off that exposes 5 mm and whose rival refuses it anyway) and
    # without its twin probe and its wide re-descent (each finds the needle).
    fitter = PoseFitter(st, MODEL, probe_rivals=False, probe_twin=False, probe_wide=False)
    twin = fitter.fit(*occ, short, **kw).T_cam_needle
    hw = MODEL.wire_radius * st.left.fx / T[2, 3]
    truth = arc_exposure(imgs, tuple(occ), st, T, MODEL, hw)
    wrong = arc_exposure(imgs, tuple(occ), st, twin, MODEL, hw)
    assert truth.worst == 0.0
    # Here the twin's course stays near the hidden wire in both images: 2.8 mm of it shows
    # over background, over the refusal threshold since session 18 (1 mm since session 19,
    # 2 mm in session 18, 3.5 mm before; the twins of the held needle at the Task 3 start
    # expose 6-9 mm).
    assert wrong.both > 0.002 and wrong.both > 2 * truth.both
    assert MAX_EXPOSED < wrong.both


def test_tissue_model_hides_what_the_block_is_in_front_of():
    from suture_bt.geometry.phantom import TISSUE_TOP_Z
    from suture_bt.perception.unseen_arc import tissue_model

    eye = np.array([0.0, 0.0, 0.2])
    block = ((-0.045, 0.045), (-0.055, 0.075))
    inside = tissue_model(np.eye(4), [], eye, block)
    top = TISSUE_TOP_Z
    pts = np.array(
        [
            [0.0, 0.0, top - 0.005],  # in the block
            [0.048, 0.0, top - 0.01],  # beyond its edge, behind it as the camera looks
            [0.06, 0.0, top - 0.01],  # beyond its edge, in plain view past it
            [0.0, 0.0, top + 0.01],  # above it
        ]
    )
    assert inside(pts).tolist() == [True, True, False, False]
    assert inside(pts, margin=0.0015).tolist() == [True, False, False, False]


def test_localizer_refuses_the_mirror_twin_of_the_held_needle_at_the_task3_start(monkeypatch):
    """Development scene (seed 6173, held_start #6): with the working floor at 50 mm (the
    needle is 46 mm away) the localiser used to answer the tilt-mirror twin 19.5 mm / 173 deg
    off (residual 0.43 px, passing every other gate); its arc runs 6 mm over the tissue in
    front of which the needle is held. With the task's tissue model that is a refusal naming
    it (without one, any tissue-coloured pixel may hide the needle and this twin is not
    caught). The floor is 20 mm now, and the needle's own pose is found."""
    import pytest
    from perception_helpers import task_scene

    from suture_bt.perception import needle_localizer, needle_masks
    from suture_bt.perception.needle_localizer import NeedleLocalizer
    from suture_bt.perception.pose_fit import NeedleNotFound

    monkeypatch.setattr(needle_localizer, "MIN_DEPTH", 0.05)
    monkeypatch.setattr(needle_masks, "MIN_DEPTH", 0.05)
    stereo_model, left, right, _, _, tissue = task_scene("held_start", 6)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    # The rival gate refuses this twin first (a pose 52 deg away costs 1.16x), and since
    # session 51 the valley gate (a pose tilted 5 deg away at 1.021x): off here, so the
    # exposure test is the one that speaks.
    loc.gates = AnswerGates(max_rival_ratio=0.0, max_valley_ratio=0.0)
    with pytest.raises(NeedleNotFound, match="hidden by nothing"):
        loc.localize(left, right)
    # With the gates on, one of them refuses it (since session 18 keeps the swage band that
    # hugs the jaw in the mask, the fit's final twin has no close rival left; the valley gate
    # or the exposure gate speaks).
    with pytest.raises(NeedleNotFound, match="another pose|hidden by nothing|a pose tilted"):
        NeedleLocalizer(stereo_model, tissue=tissue).localize(left, right)


def test_a_needle_whose_tip_the_tissue_hides_and_base_the_jaw_is_not_answered_slid():
    """Held-out 36796497 ``held_start`` #29 as the fit saw it (no priors): a Task 3 start
    43 mm away, its base end in PSM2's jaw and its tip dipping 0.6 mm into the moved
    phantom's top at 27°. The fit once answered 0.04 mm / 5.9 deg off, slid along its circle,
    with a predicted spread of 0.09 deg: the tissue's cut set its rounded end back to the
    surface, where a wire entering this shallowly still shows its top, so the wire's end at the
    tissue was taken for the tip. With the cut's end where the wire's top goes under
    (:func:`~suture_bt.perception.tissue_cut._entry_setback`) nothing seen pins the slide:
    the call is refused (spread), or would have to be answered right."""
    fitter, args, kwargs, T = recorded_fit("tissue_hidden_tip_slide")
    fit = fitter.fit(*args, **kwargs)
    try:
        FitAttempts(fitter.stereo, fitter.model, None, fitter, AnswerGates())._check(fit, ())
    except NeedleNotFound:
        return
    errors = min(pose_errors(fit.T_cam_needle, P) for P in (T, fitter.model.swapped(T)))
    assert errors[1] < 5.0, f"answered {errors[0]:.2f} mm / {errors[1]:.1f} deg off"
