"""Offset compensation signs follow DESIGN.md §5: with Δq̂ = Δq the true joints equal the desired."""

import numpy as np
import pytest

from suture_bt.control import command_for_true, full_offset, true_from_measured

DQ = np.array([np.deg2rad(2.52), np.deg2rad(-0.46), 0.004])  # SRC condition B


def arm_with_offset(q_cmd, dq):
    """The offset model: the arm goes to q_cmd + Δq and reports q_actual − Δq."""
    q_actual = np.asarray(q_cmd) + full_offset(dq)
    return q_actual, q_actual - full_offset(dq)


def test_exact_estimate_puts_true_joints_at_desired():
    q_d = np.array([0.2, -0.1, 0.12, 0.4, -0.2, 0.3])
    q_actual, q_meas = arm_with_offset(command_for_true(q_d, DQ), DQ)
    np.testing.assert_allclose(q_actual, q_d, atol=1e-15)
    np.testing.assert_allclose(true_from_measured(q_meas, DQ), q_actual, atol=1e-15)
    # The reading alone hides the bias: it equals the command, not the true joints.
    np.testing.assert_allclose(q_meas, command_for_true(q_d, DQ), atol=1e-15)


def test_wrong_sign_or_no_estimate_leaves_the_bias():
    q_d = np.zeros(6)
    q_actual, _ = arm_with_offset(command_for_true(q_d, np.zeros(3)), DQ)
    np.testing.assert_allclose(q_actual[:3], DQ)
    q_actual, _ = arm_with_offset(command_for_true(q_d, -DQ), DQ)
    np.testing.assert_allclose(q_actual[:3], 2 * DQ)


def test_full_offset_shapes():
    np.testing.assert_array_equal(full_offset([1.0, 2.0, 3.0]), [1, 2, 3, 0, 0, 0])
    np.testing.assert_array_equal(full_offset(np.r_[DQ, 0, 0, 0])[:3], DQ)
    with pytest.raises(ValueError, match="joints 1-3"):
        full_offset([0, 0, 0, 0.1, 0, 0])
    with pytest.raises(ValueError, match="3"):
        full_offset([1.0, 2.0])
