"""The low-level servo leaves the documented steady-state error, from friction and load."""

import numpy as np
import pytest

from suture_bt.sim.joint_servo import JointServo, ServoParams

Q0 = np.array([0.3, -0.2, 0.12, 0.5, -0.3, 0.1])


def _settle(servo: JointServo, seconds: float = 2.0) -> None:
    for _ in range(int(seconds * 1000)):
        servo.step(1e-3)


@pytest.mark.parametrize("joint", [0, 1, 3, 4, 5])
@pytest.mark.parametrize("step", [0.1, -0.3, 0.5])
def test_revolute_step_leaves_about_1p5_deg(joint, step):
    servo = JointServo(Q0)
    servo.setpoint = Q0.copy()
    servo.setpoint[joint] += step
    _settle(servo)
    err = np.rad2deg(abs(servo.setpoint[joint] - servo.q[joint]))
    # Documented: 1.5° on friction-only joints, 0.9°-2.1° on the loaded outer pitch.
    lo, hi = (0.85, 2.15) if joint == 1 else (1.4, 1.6)
    assert lo <= err <= hi
    assert abs(servo.qd[joint]) < 1e-9  # truly at rest: the error is steady
    # The other joints did not move.
    others = [i for i in range(6) if i != joint]
    assert np.allclose(servo.q[others], Q0[others], atol=1e-4)


@pytest.mark.parametrize("step", [0.01, -0.03, 0.05])
def test_insertion_step_leaves_about_0p1_mm(step):
    servo = JointServo(Q0)
    servo.setpoint = Q0.copy()
    servo.setpoint[2] += step
    _settle(servo)
    err_mm = abs(servo.setpoint[2] - servo.q[2]) * 1e3
    assert 0.04 <= err_mm <= 0.16


def test_error_comes_from_friction_not_a_constant():
    # Without friction and load the same controller reaches the set-point.
    servo = JointServo(Q0, ServoParams(revolute_friction_deg=0.0, prismatic_friction_mm=0.0))
    servo.setpoint = Q0 + np.array([0.2, 0.2, 0.02, 0.2, 0.2, 0.2])
    _settle(servo, 3.0)
    assert np.allclose(servo.q, servo.setpoint, atol=1e-6)


def test_limited_bandwidth_and_load_direction():
    servo = JointServo(Q0)
    servo.setpoint = Q0 + np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.0])
    for _ in range(20):  # 20 ms after the step: far from the goal
        servo.step(1e-3)
    assert servo.q[1] - Q0[1] < 0.1
    _settle(servo)
    up_err = servo.setpoint[1] - servo.q[1]
    servo2 = JointServo(Q0)
    servo2.setpoint = Q0 - np.array([0.0, 0.3, 0.0, 0.0, 0.0, 0.0])
    _settle(servo2)
    down_err = servo2.q[1] - servo2.setpoint[1]
    # The load pulls against one direction: the two errors differ.
    assert up_err > down_err + np.deg2rad(0.5)


def test_ideal_servo_is_exact():
    servo = JointServo(Q0, ServoParams(ideal=True))
    servo.setpoint = Q0 + 0.1
    servo.step(1e-3)
    assert np.array_equal(servo.q, servo.setpoint)
