"""In-hand transform: exact round trip, grasped arc angle, and the hidden-offset caveat."""

import numpy as np
import pytest

from suture_bt.datagen.needle_data import grasp_transform
from suture_bt.geometry import NeedleModel
from suture_bt.kinematics import forward_kinematics
from suture_bt.perception.in_hand import estimate_in_hand, in_hand_transform
from suture_bt.transforms import pose_to_transform

BASE = pose_to_transform((0.1, 0.1346, 0.135), (0.6981, -0.5236, -np.pi))
Q = np.array([0.3, -0.2, 0.14, 1.0, -0.3, 0.2])


def test_in_hand_recovers_the_grasp_and_its_arc_angle():
    model = NeedleModel()
    T_tip_needle = grasp_transform(model, 2.6, flip=False)
    cp = forward_kinematics(Q)
    T_world_needle = BASE @ cp @ T_tip_needle
    est = estimate_in_hand(T_world_needle, cp, BASE, model)
    np.testing.assert_allclose(est.T_tip_needle, T_tip_needle, atol=1e-12)
    assert est.grasp_arc_angle == pytest.approx(2.6, abs=0.005)
    assert est.jaw_distance < 1e-4 and est.plausible


def test_uncompensated_offset_biases_the_in_hand_transform():
    model = NeedleModel()
    true_cp = forward_kinematics(Q)
    T_world_needle = BASE @ true_cp @ grasp_transform(model, 2.6, flip=False)
    # Joints 1-2 swing the jaw sideways (an insertion offset slides it along the blades).
    dq = np.array([np.deg2rad(2.0), np.deg2rad(2.0), 0.0, 0, 0, 0])
    est = estimate_in_hand(T_world_needle, forward_kinematics(Q - dq), BASE, model)
    assert est.jaw_distance > 0.003 and est.blade_distance > 0.003 and not est.plausible


def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match="measured_cp"):
        in_hand_transform(np.eye(4), np.full((4, 4), np.nan), np.eye(4))


def test_uncalibrated_estimate_says_it_holds_only_where_measured():
    model = NeedleModel()
    cp = forward_kinematics(Q)
    T_world_needle = BASE @ cp @ grasp_transform(model, 2.6, flip=False)
    moved = forward_kinematics(Q + np.array([0.05, 0, 0, 0, 0, 0]))
    unknown = estimate_in_hand(T_world_needle, cp, BASE, model)
    assert (
        unknown.valid_only_where_measured and unknown.valid_at(cp) and not unknown.valid_at(moved)
    )
    calibrated = estimate_in_hand(T_world_needle, cp, BASE, model, calibrated=True)
    assert not calibrated.valid_only_where_measured and calibrated.valid_at(moved)


def test_uncalibrated_margin_keeps_a_correct_estimate_plausible():
    """The offset's tip error, given in the margin, no longer reads as an implausible grasp."""
    model = NeedleModel()
    true_cp = forward_kinematics(Q)
    T_world_needle = BASE @ true_cp @ grasp_transform(model, 2.6, flip=False)
    measured_cp = forward_kinematics(Q - np.array([np.deg2rad(2.0), 0, 0.003, 0, 0, 0]))
    from suture_bt.skills.tip_uncertainty import worst_offset_displacement

    margin = 0.001 + worst_offset_displacement(Q)
    est = estimate_in_hand(T_world_needle, measured_cp, BASE, model, margin, calibrated=False)
    assert est.plausible and est.valid_only_where_measured


def test_a_wire_held_deeper_along_the_blades_is_plausible_one_beside_them_is_not():
    model = NeedleModel()
    cp = forward_kinematics(Q)
    T_tip_needle = grasp_transform(model, 2.6, flip=False)
    cases = ((np.array([0.0, 0.0, -0.0025]), True), (np.array([0.0, 0.0025, 0.0]), False))
    for shift, plausible in cases:
        T = T_tip_needle.copy()
        T[:3, 3] += shift  # the needle moved in the tip frame: along the blades, or off them
        est = estimate_in_hand(BASE @ cp @ T, cp, BASE, model, max_jaw_distance=0.002)
        assert est.jaw_distance == pytest.approx(0.0025, abs=2e-4)
        assert est.plausible is plausible, (shift, est.blade_distance)
