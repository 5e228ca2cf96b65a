"""The localisation pipeline: empty images give NeedleNotFound (never another exception),
bad inputs a clear ValueError, and (with the shipped weights) a rendered needle is found."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from perception_helpers import pose_errors, stereo, task_scene

from suture_bt.perception import pose_fit
from suture_bt.perception.answer_gates import AnswerGates
from suture_bt.perception.needle_localizer import (
    HELD_PIN_TOLERANCE,
    MAX_ANGLE_STD_DEG,
    MAX_ANGLE_STD_DEG_HELD,
    MAX_ANGLE_STD_DEG_UNAIDED,
    NeedleLocalizer,
)
from suture_bt.perception.needle_prior import HeldPrior, PortPrior
from suture_bt.perception.network import DEFAULT_WEIGHTS, NeedleNet
from suture_bt.perception.pose_fit import NeedleNotFound
from suture_bt.transforms import invert


def _blind_net() -> NeedleNet:
    """A network that never fires (all output biases very negative)."""
    torch.manual_seed(0)
    net = NeedleNet(width=8)
    with torch.no_grad():
        net.head.weight.zero_()
        net.head.bias.fill_(-20.0)
    return net.eval()


def _eager_net() -> NeedleNet:
    """A network that marks every pixel as needle."""
    net = _blind_net()
    with torch.no_grad():
        net.head.bias.fill_(20.0)
    return net


@pytest.mark.parametrize("make", [_blind_net, _eager_net])
def test_empty_image_raises_needle_not_found(make):
    loc = NeedleLocalizer(stereo(640, 360), net=make())
    black = np.zeros((360, 640, 3), np.uint8)
    pink = np.full((360, 640, 3), (215, 140, 132), np.uint8)
    for img in (black, pink):
        with pytest.raises(NeedleNotFound) as info:
            loc.localize(img, img)
        assert info.value.reason


def test_bad_image_is_a_value_error():
    loc = NeedleLocalizer(stereo(640, 360), net=_blind_net())
    with pytest.raises(ValueError, match="left image"):
        loc.localize(np.zeros((360, 640), np.uint8), np.zeros((360, 640, 3), np.uint8))
    img = np.zeros((360, 640, 3), np.uint8)
    for bad in (np.eye(3), np.full((4, 4), np.nan)):
        with pytest.raises(ValueError, match="previous must be a finite 4×4"):
            loc.localize(img, img, previous=bad)


def test_shipped_network_localizes_a_rendered_needle():
    if not DEFAULT_WEIGHTS.is_file():
        pytest.fail(f"shipped weights missing: {DEFAULT_WEIGHTS}")
    from suture_bt.datagen.needle_data import SimScene

    sim = SimScene(960, 540)
    try:
        for i in range(40):  # the first seeded scene whose needle is in full view
            rng = np.random.default_rng([2024, i])
            s = sim.sampler.sample(rng, scenario="free", zr=(0.08, 0.12))
            s = s.__class__(s.scenario, s.T_world_needle, s.q, s.jaw, 1.0, 2.0)
            sim.apply(s)
            left, mask = sim.render("left", s, rng)
            if mask.sum() > 300:
                break
        else:
            pytest.fail("no seeded scene shows the needle")
        right, _ = sim.render("right", s, rng)
        est = NeedleLocalizer(sim.stereo).localize(left, right)
        strict = NeedleLocalizer(sim.stereo, gates=AnswerGates(max_rms_px=0.0))
        with pytest.raises(NeedleNotFound, match="RMS"):  # a fit worse than allowed is refused
            strict.localize(left, right)
        with pytest.raises(NeedleNotFound, match="leaves the pose loose"):  # and a loose one
            strict.localize(left, right, gates=AnswerGates(max_angle_std_deg=0.0))
        # Gates given for one call replace the localiser's for that call only.
        again = strict.localize(left, right, gates=AnswerGates())
        np.testing.assert_array_equal(again.T_cam_needle, est.T_cam_needle)
        assert strict.gates.max_rms_px == 0.0
        with pytest.raises(NeedleNotFound, match="holds something else"):  # and one that
            # explains too little of the mask
            strict.localize(left, right, gates=AnswerGates(min_inlier_fraction=1.01))
        T_true = invert(sim.stereo.left.T_world_cam) @ s.T_world_needle
    finally:
        sim.close()
    pos, ang = pose_errors(est.T_cam_needle, T_true)
    assert pos < 2.0 and ang < 5.0  # base and tip told apart (the swage band's colour)
    assert est.end_decided_by == "colour"
    assert est.timings_ms["total"] > 0
    # A needle in full view is pinned tightly: its predicted spread is well inside the limit.
    assert 0 < est.angle_std_deg < 1.0 and 0 < est.position_std_mm < 1.0


def test_keypoints_farther_apart_than_the_needle_can_appear_keep_only_the_stronger():
    """At 1080p the needle's ends are at most ~340 px apart (its chord at 50 mm, with
    slack): a pair 900 px apart has one keypoint on something else, the weaker is dropped."""
    loc = NeedleLocalizer(stereo(1920, 1080), net=_eager_net())
    kp = np.array([[[830.0, 220.0], [1750.0, 220.0]], [[800.0, 220.0], [900.0, 230.0]]])
    score = np.array([[0.87, 0.47], [0.6, 0.7]])
    out = loc.plausible(kp, score)
    np.testing.assert_array_equal(out, [[0.87, 0.0], [0.6, 0.7]])
    assert score[0, 1] == 0.47  # the raw scores are left alone
    far_weak = np.array([[0.1, 0.9], [0.6, 0.7]])  # an untrusted keypoint is no rival
    np.testing.assert_array_equal(loc.plausible(kp, far_weak), far_weak)


def test_of_two_keypoints_too_far_apart_the_one_on_a_speck_is_dropped_even_if_stronger():
    """The stronger keypoint may sit on another instrument's jaw tip (a speck of the coarse
    mask) and the weaker on the needle's arc (a long blob): the speck's is dropped."""
    loc = NeedleLocalizer(stereo(1920, 1080), net=_eager_net())
    kp = np.array([[[830.0, 220.0], [1750.0, 220.0]], [[800.0, 220.0], [900.0, 230.0]]])
    score = np.array([[0.3, 0.8], [0.6, 0.7]])
    scale = 8.0
    prob = np.zeros((2, 136, 240))
    (u0, v0), (u1, v1) = np.rint((kp[0] + 0.5) / scale - 0.5).astype(int)
    prob[0, v1 - 1 : v1 + 2, u1 - 1 : u1 + 2] = 0.9  # a 3×3 speck under the stronger
    prob[0, v0 - 1 : v0 + 2, u0 - 1 : u0 + 25] = 0.9  # an arc-long blob under the weaker
    out = loc.plausible(kp, score, prob, scale)
    np.testing.assert_array_equal(out, [[0.3, 0.0], [0.6, 0.7]])
    np.testing.assert_array_equal(loc.plausible(kp, score), [[0.0, 0.8], [0.6, 0.7]])


def test_without_priors_the_spread_limit_is_tighter_and_a_pinned_holder_loosens_it():
    """Nothing but the image checks the plane of an answer given without priors; a calibrated
    held-by prior pins a point of the arc and allows a looser spread."""
    loc = NeedleLocalizer(stereo(1920, 1080), net=_eager_net())
    port = PortPrior("entry 1", np.zeros(3), 0.002)
    pinned = HeldPrior("psm2", np.zeros(3), HELD_PIN_TOLERANCE)
    assert loc.gates.angle_std_limit(()) == pytest.approx(MAX_ANGLE_STD_DEG_UNAIDED)
    assert loc.gates.angle_std_limit((port,)) == pytest.approx(MAX_ANGLE_STD_DEG)
    assert loc.gates.angle_std_limit((pinned,)) == pytest.approx(MAX_ANGLE_STD_DEG_HELD)
    assert MAX_ANGLE_STD_DEG_UNAIDED < MAX_ANGLE_STD_DEG < MAX_ANGLE_STD_DEG_HELD
    unlimited = NeedleLocalizer(
        stereo(1920, 1080), net=_eager_net(), gates=AnswerGates(max_angle_std_deg=np.inf)
    )
    assert unlimited.gates.angle_std_limit(()) == np.inf


def test_a_new_tissue_model_gives_the_fit_its_solid():
    """A caller whose phantom moved sets the localiser's tissue; the fit's cut then hides the
    arc inside the new phantom's solid, not the old one's."""
    from suture_bt.geometry import PhantomModel
    from suture_bt.perception.unseen_arc import phantom_tissue
    from suture_bt.transforms import make_transform

    st = stereo(1920, 1080)
    eye = st.left.T_world_cam[:3, 3]
    old = phantom_tissue(PhantomModel(), eye)
    loc = NeedleLocalizer(st, net=_eager_net(), tissue=old)
    assert loc.fitter.tissue_solid is old.pieces
    moved = phantom_tissue(PhantomModel(make_transform(position=(0.01, 0.0, 0.0))), eye)
    loc.tissue = moved
    assert loc.tissue is moved and loc.fitter.tissue_solid is moved.pieces
    loc.tissue = None
    assert loc.fitter.tissue_solid is None


def test_a_held_needle_30_mm_from_the_cameras_is_localised(monkeypatch):
    """The Task 3 start holds the needle 27-50 mm from the left eye, nearly edge-on (the
    working floor was 50 mm: every such view was refused). Scene 19 (29 mm) is answered
    without priors; in scene 3 (36 mm) every candidate of the image's own search misses the
    holder's pinch point, and the starts the held-by and across-the-jaws priors seed
    (:func:`~suture_bt.perception.needle_prior.seed_poses`) reach the needle."""
    from suture_bt.perception import fit_attempts
    from suture_bt.perception.needle_prior import PriorContradicted

    stereo_model, left, right, T, priors, tissue = task_scene("held_start", 19)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    est = loc.localize(left, right)
    assert T[2, 3] < 0.03
    pos, ang = pose_errors(est.T_cam_needle, T)
    assert pos < 0.5 and ang < 2.0
    stereo_model, left, right, T, priors, tissue = task_scene("held_start", 3)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    pos, ang = pose_errors(loc.localize(left, right, priors=priors).T_cam_needle, T)
    assert pos < 0.5 and ang < 2.0
    monkeypatch.setattr(fit_attempts, "seed_poses", lambda *a: np.zeros((0, 4, 4)))
    with pytest.raises(PriorContradicted, match="pinch point"):
        loc.localize(left, right, priors=priors)


def test_grey_where_the_wire_goes_into_the_tissue_does_not_say_tip():
    """A needle in a port (development scene 15 of the in_port set, 47 mm away, its base in
    the tissue past the entry): the fitted end where the wire goes into the tissue is not its
    tip. That grey used to vote "tip here" and the answer was the needle with base and tip
    swapped (180 deg off); now it is the needle or a refusal."""
    stereo_model, left, right, T, priors, tissue = task_scene("in_port", 15)
    # The exposure gate off: since session 19 (1 mm) it refuses this fit before the base-or-tip
    # choice, which is what is tested here. So are the rival, tie and spread gates: since
    # session 20 the scene's grasp is drawn off where it was meant, and the slide along the
    # circle this view leaves loose (8-10 deg at 1.00x the cost) refuses it first; since
    # session 51 also a pose tilted 5 deg from it at 1.011x the cost (the valley gate).
    loose = AnswerGates(
        max_exposed=float("inf"),
        max_rival_ratio=0.0,
        max_tie_ratio=0.0,
        max_tie_ratio_far=0.0,
        max_tie_ratio_short=0.0,
        max_angle_std_deg=1e3,
        max_position_std_mm=1e3,
        max_valley_ratio=0.0,
    )
    loc = NeedleLocalizer(stereo_model, tissue=tissue, gates=loose)
    try:
        est = loc.localize(left, right)
    except NeedleNotFound as exc:
        assert "which end is the base" in exc.reason
    else:
        pos, ang = pose_errors(est.T_cam_needle, T)
        _, ang_swapped = pose_errors(est.T_cam_needle, loc.model.swapped(T))
        assert pos < 2.0 and ang < ang_swapped  # the needle, perhaps slid along its circle


def test_a_needle_in_a_port_with_both_ends_hidden_is_localised_with_its_priors():
    """Development scene 7 of the in_port set: the base in the tissue past the exit, the tip
    behind the pulling jaw. The outline's end at the port drew the fit to a pose slid along
    its circle, which the grasp's held place refused (session 20); measured to the seen arc
    (the ports' tissue cut) and seeded by the circles through pinch and port, it is found."""
    stereo_model, left, right, T, priors, tissue = task_scene("in_port", 7)
    est = NeedleLocalizer(stereo_model, tissue=tissue).localize(left, right, priors=priors)
    pos, ang = pose_errors(est.T_cam_needle, T)
    assert pos < 1.0 and ang < 4.0  # 0.30 mm / 2.7 deg


def test_a_needle_cut_off_by_the_tissues_silhouette_is_not_answered_slid_to_the_cut():
    """Development scene 46 of the occluded set (seed 1000): an edge-on needle seen over the
    dark cavity, its tip behind the ridge, its base behind a jaw. The mask's end at the ridge
    was explained as the needle's own end: answered 1.5 mm / 9.6° off with a predicted spread
    of 0.2° (session 22). With the cut at the silhouette left out of the outline it is right or
    refused, never that confident wrong answer."""
    stereo_model, left, right, T, _, tissue = task_scene("occluded", 46, seed=1000)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    try:
        est = loc.localize(left, right)
    except NeedleNotFound:
        return
    pos, ang = pose_errors(est.T_cam_needle, T)
    assert pos < 2.0 and ang < 5.0


def test_a_keypoint_on_the_arcs_bulge_does_not_lead_to_a_confident_mirror_answer(monkeypatch):
    """Session 25's report seed 27322476, ``unoccluded`` #0: a free needle 174 mm away, its
    ends 18 px apart in the image, its bulge 43 px across. The base keypoint sat on the
    bulge's far extreme, the mask's far pair too, and stereo said 136 mm: the answer was
    7.7 mm / 171° off, passing every gate. Its ends had moved 20.7 px from every hypothesis;
    refit from them it is the needle (since session 34 the wide re-descent reaches it too, and
    since session 40 the fit's second search from its best pose's ends, far from a keypoint)."""
    stereo_model, left, right, T, _, tissue = task_scene("unoccluded", 0, seed=27322476)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    est = loc.localize(left, right)
    pos, ang = pose_errors(est.T_cam_needle, T)
    assert pos < 1.0 and ang < 1.0  # 0.58 mm / 0.20 deg
    loc.gates = AnswerGates(refit_moved_px=float("inf"))
    loc.fitter.probe_wide = False
    est = loc.localize(left, right)
    assert pose_errors(est.T_cam_needle, T)[1] < 5.0  # the second search alone: 3.7 deg
    monkeypatch.setattr(pose_fit, "RESEED_MOVED_PX", float("inf"))
    est = loc.localize(left, right)
    assert pose_errors(est.T_cam_needle, T)[1] > 90.0  # the old answer, for the record


def test_an_edge_on_needle_is_not_answered_as_its_depth_mirror_twin():
    """Session 26's occluded-rate seed 6289076, ``occluded`` #283: a held needle seen nearly
    edge-on, 119 mm away. No start of the search fell into its basin, and its depth-mirror
    twin (the same end pixels, the arc turned to -psi) was answered 14.4 mm / 146° off with a
    predicted spread of 0.17°. The twin probe descends from the answer's twin and finds it."""
    stereo_model, left, right, T, _, tissue = task_scene("occluded", 283, seed=6289076)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    est = loc.localize(left, right)
    pos, ang = pose_errors(est.T_cam_needle, T)
    assert pos < 0.5 and ang < 0.5  # 0.15 mm / 0.1 deg
    loc.fitter.probe_twin = False
    est = loc.localize(left, right)
    assert pose_errors(est.T_cam_needle, T)[1] > 90.0  # the old answer, for the record


def test_a_highlight_in_one_eye_does_not_set_the_needles_depth():
    """Session 26's occluded-rate seed 11493571, ``occluded`` #123: a needle held by PSM1,
    85 mm away; a white highlight on the jaw joins the right eye's mask. It dragged the masks'
    disparity to 39 mm, which overruled the keypoints' 96 mm, widened the thickness gate to
    keep the highlight, and the arc bent into it: 1.4 mm / 7.7° off, spread 0.14°. The wire's
    own thickness (3 px: a wire about 90 mm away) says which depth to believe. Since session
    45 the answer is refused as a far tie (a pose clearly apart at 1.054x its cost, 85 mm
    away: the far limit is 1.10); answered under the near limit, it is the needle's. (A pose
    tilted 5 deg from it costs 1.031x: the valley gate, session 51, refuses it there too; a
    right answer at that ratio, as close to the limit as any development answer came.)"""
    stereo_model, left, right, T, _, tissue = task_scene("occluded", 123, seed=11493571)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    with pytest.raises(NeedleNotFound, match=r"1\.05\d\dx the answer's, limit 1\.10 at 8\d mm"):
        loc.localize(left, right)
    with pytest.raises(NeedleNotFound, match=r"tilted 5 deg .*cost 1\.031\dx"):
        loc.localize(left, right, gates=replace(loc.gates, far_tie_depth=float("inf")))
    near = replace(loc.gates, far_tie_depth=float("inf"), max_valley_ratio=0.0)
    est = loc.localize(left, right, gates=near)
    pos, ang = pose_errors(est.T_cam_needle, T)
    assert pos < 1.0 and ang < 2.5  # 0.28 mm / 1.3 deg


def test_a_jaw_blade_beside_the_needle_does_not_make_a_confident_wrong_answer():
    """Session 32's report seed 90624406, ``occluded`` #27: a needle held in a jaw 106 mm
    away, its band and a short stretch of wire seen. A piece of the jaw's lit blade beside it
    (43 px left, 115 px right) was taken for wire; the fit bent the arc through it and answered
    7.4 mm / 45° off with a 0.39° predicted spread. Fitted without that piece, the seen
    stretch leaves the pose loose: refused, with the reason."""
    stereo_model, left, right, T, _, tissue = task_scene("occluded", 27, seed=90624406)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    with pytest.raises(NeedleNotFound, match="did not explain as wire"):
        loc.localize(left, right)
    loc.drop_stray_pieces = False
    est = loc.localize(left, right)
    assert pose_errors(est.T_cam_needle, T)[1] > 30.0  # the old answer, for the record


def test_an_answer_in_a_narrow_basin_is_descended_again_from_the_searchs_wide_stage():
    """Development seed 93896709, ``held_start`` #24 with its priors: the needle in PSM2's jaw
    at the Task 3 start. The search's answer sat in a narrow basin 5.2 deg off, turned along
    the needle's circle, that no probe left (each descends at 1 px); taken back through the
    search's own 3 px stage (``answer_probes.wide_redescent``), it comes 3.0 deg off. Since
    session 41 the mask holds the wire the network's mask stopped short of
    (:mod:`~suture_bt.perception.wire_growth`), and it is answered 0.04 deg off without the
    re-descent; the re-descent's case is the record's mask."""
    stereo_model, left, right, T, priors, tissue = task_scene("held_start", 24, seed=93896709)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    loc.fitter.probe_wide = False
    pos, ang = pose_errors(loc.localize(left, right, priors=priors).T_cam_needle, T)
    assert pos < 0.5 and ang < 1.0  # the whole wire seen: 0.01 mm / 0.04 deg
    loc.halve_near = False  # the record's resolution (near_view)
    loc.grow_wire = False  # the record's mask
    loc.fitter.probe_wide = True
    pos, ang = pose_errors(loc.localize(left, right, priors=priors).T_cam_needle, T)
    assert pos < 0.5 and ang < 4.0  # 0.01 mm / 3.0 deg
    loc.fitter.probe_wide = False
    loc.window_right = False  # the record's network reading: the right eye read whole
    est = loc.localize(left, right, priors=priors)
    assert pose_errors(est.T_cam_needle, T)[1] > 5.0  # the old answer, for the record


def test_a_held_needle_pushed_into_the_tissue_is_refused_not_slid_to_its_surface():
    """Report seed 82330937 (session 34), ``held_start`` #68 with its priors: PSM2's offset
    put the needle's tip 2.6 mm of arc into the tissue, its base end under the jaw. The fit put
    the tip where the wire meets the tissue, 14 deg off along the circle; slid up to 8 deg
    into the tissue the arc shows the same wire and still passes the pinch point
    (``tissue_slide``): refused, saying so. Since session 53 the tissue's cut shows the wire's
    top past the surface at a shallow entry, so the fit itself finds the slide nearly free: a
    rival 34 deg along the circle at 1.02x refuses it first, and without the rival and tie
    gates the tissue slide still does."""
    stereo_model, left, right, T, priors, tissue = task_scene("held_start", 68, seed=82330937)
    loc = NeedleLocalizer(stereo_model, tissue=tissue)
    with pytest.raises(NeedleNotFound, match=r"another pose .* 34 deg away .*cost 1\.02x"):
        loc.localize(left, right, priors=priors)
    loc.gates = replace(loc.gates, max_rival_ratio=0.0, max_tie_ratio=1.0)
    with pytest.raises(NeedleNotFound, match="meets the tissue and the needle may go on into it"):
        loc.localize(left, right, priors=priors)
    loc.gates = replace(loc.gates, max_tissue_slide_deg=float("inf"))
    est = loc.localize(left, right, priors=priors)
    assert pose_errors(est.T_cam_needle, T)[1] > 10.0  # the old answer, for the record
