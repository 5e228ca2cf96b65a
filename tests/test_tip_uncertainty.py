"""The tip's worst displacement under the task's offset bound, and the margin it gives."""

from types import SimpleNamespace

import numpy as np
import pytest

from suture_bt.calibration.calibration_pose import OFFSET_BOUND
from suture_bt.kinematics import forward_kinematics
from suture_bt.skills.tip_uncertainty import tip_margin, worst_offset_displacement

Q = np.array([-0.4, -0.22, 0.139, -1.64, -0.37, -0.11])


def test_no_offset_in_the_bound_moves_the_tip_further():
    worst = worst_offset_displacement(Q)
    rng = np.random.default_rng(3)
    tip = forward_kinematics(Q)[:3, 3]
    for dq in rng.uniform(-1.0, 1.0, (200, 3)) * OFFSET_BOUND:
        q = Q.copy()
        q[:3] += dq
        assert np.linalg.norm(forward_kinematics(q)[:3, 3] - tip) <= worst + 1e-12


def test_a_deeper_tool_swings_further():
    deep = Q.copy()
    deep[2] += 0.05
    assert worst_offset_displacement(deep) > worst_offset_displacement(Q) + 0.005


@pytest.mark.parametrize("calibrated", [True, False])
def test_the_margin_is_zero_once_calibrated(calibrated):
    arm = SimpleNamespace(calibrated=calibrated, servo=SimpleNamespace(estimated_jp=lambda: Q))
    margin = tip_margin(arm)
    assert (margin == 0.0) if calibrated else margin == worst_offset_displacement(Q)


def test_offset_displacements_hold_the_zero_offset_and_reach_the_worst_corner():
    from suture_bt.skills.tip_uncertainty import offset_displacements

    q = np.array([-0.4, -0.22, 0.139, -1.64, -0.37, -0.11])
    d = offset_displacements(q, levels=2)
    assert d.shape == (9, 3)
    np.testing.assert_allclose(d[0], 0.0)
    assert np.linalg.norm(d, axis=1).max() == pytest.approx(worst_offset_displacement(q))


def test_tip_displacements_of_the_zero_offset_are_zero():
    from suture_bt.skills.tip_uncertainty import tip_displacements

    q = np.array([-0.4, -0.22, 0.139, -1.64, -0.37, -0.11])
    np.testing.assert_allclose(tip_displacements(q, np.zeros((1, 3))), 0.0, atol=1e-15)
