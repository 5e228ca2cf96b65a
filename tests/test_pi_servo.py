"""PI servo on fake arms: removes a load error, compensates offsets, anti-windup, observability."""

import numpy as np
import pytest

from suture_bt.control import PIGains, PIServo, full_offset
from suture_bt.kinematics import JOINT_LIMITS

Q0 = np.array([0.3, -0.2, 0.12, 0.5, -0.3, 0.1])
LOAD = np.array(
    [np.deg2rad(1.5), -np.deg2rad(1.2), 0.0001, np.deg2rad(1.5), -np.deg2rad(1.5), 0.02]
)
DQ_B = np.array([np.deg2rad(2.52), np.deg2rad(-0.46), 0.004])
PHYSICS_DT = 0.001


class LaggingArm:
    """First-order lag (τ) toward command + Δq, pulled back by a constant load; reads q − Δq."""

    def __init__(self, q0=Q0, tau=0.03, load=LOAD, offset=(0.0, 0.0, 0.0)):
        self.offset = full_offset(offset)
        self.q = np.array(q0, dtype=float) + self.offset
        self.cmd = np.array(q0, dtype=float)
        self.tau, self.load = tau, np.asarray(load, dtype=float)
        self.blocked = np.zeros(6, dtype=bool)
        self.commands = 0

    def measured_jp(self):
        return self.q - self.offset

    def servo_jp(self, q):
        q = np.asarray(q, dtype=float)
        assert np.all(q >= JOINT_LIMITS[:, 0]) and np.all(q <= JOINT_LIMITS[:, 1])
        self.cmd = q.copy()
        self.commands += 1

    def physics_step(self):
        target = self.cmd + self.offset - self.load
        if self.tau == 0.0:
            new = target
        else:
            new = self.q + PHYSICS_DT / self.tau * (target - self.q)
        self.q = np.where(self.blocked, self.q, new)


def run(arm, servo, seconds):
    every = round(servo.dt / PHYSICS_DT)
    for k in range(round(seconds / PHYSICS_DT)):
        if k % every == 0:
            servo.update(k * PHYSICS_DT)
        arm.physics_step()


def test_pi_removes_the_load_error_that_the_low_level_leaves():
    goal = Q0 + np.array([0.1, -0.1, 0.01, 0.2, 0.1, -0.1])
    arm = LaggingArm()
    off = PIServo(arm, enabled=False)
    off.servo_jp(goal)
    run(arm, off, 1.0)
    np.testing.assert_allclose(goal - arm.q, LOAD, rtol=1e-3)  # low-level alone
    arm = LaggingArm()
    pi = PIServo(arm)
    pi.servo_jp(goal)
    run(arm, pi, 1.0)
    assert np.max(np.abs(goal - arm.q)) < 1e-6
    # The integrator holds exactly the load it compensates.
    np.testing.assert_allclose(pi.integrator, LOAD, rtol=1e-4, atol=1e-9)


@pytest.mark.parametrize("tau", [0.0, 0.01, 0.05])
def test_loop_is_stable_from_an_ideal_arm_to_a_slow_one(tau):
    arm = LaggingArm(tau=tau)
    pi = PIServo(arm)
    goal = Q0 + 0.05
    pi.servo_jp(goal)
    run(arm, pi, 1.5)
    assert np.max(np.abs(goal - arm.q)) < 1e-6


def test_offset_estimate_drives_true_joints_to_desired():
    goal = Q0 + np.array([0.05, 0.05, 0.005, 0.0, 0.0, 0.0])
    arm = LaggingArm(offset=DQ_B)
    pi = PIServo(arm, offset_estimate=DQ_B)
    pi.servo_jp(goal)
    run(arm, pi, 1.0)
    assert np.max(np.abs(arm.q - goal)) < 1e-6  # TRUE joints at the desired values
    np.testing.assert_allclose(pi.estimated_jp(), goal, atol=1e-6)
    np.testing.assert_allclose(pi.commanded[:3], goal[:3] + pi.correction[:3] - DQ_B, atol=1e-12)
    # Without the estimate the bias stays, invisible in the measurement.
    arm = LaggingArm(offset=DQ_B)
    pi = PIServo(arm)
    pi.servo_jp(goal)
    run(arm, pi, 1.0)
    np.testing.assert_allclose(arm.q[:3] - goal[:3], DQ_B, atol=1e-6)
    assert np.max(np.abs(arm.measured_jp() - goal)) < 1e-6


def _release_overshoot(block_seconds):
    """Peak overshoot of joint 1 after a 0.5 rad step that was blocked for a while."""
    arm = LaggingArm()
    pi = PIServo(arm)
    pi.servo_jp(Q0)
    run(arm, pi, 0.5)
    arm.blocked[0] = block_seconds > 0
    goal = Q0.copy()
    goal[0] += 0.5  # far beyond max_correction
    pi.servo_jp(goal)
    run(arm, pi, block_seconds)
    blocked_state = (pi.saturated[0], pi.correction[0], pi.integrator[0])
    arm.blocked[0] = False
    peak = 0.0
    every = round(pi.dt / PHYSICS_DT)
    for k in range(2000):
        if k % every == 0:
            pi.update()
        arm.physics_step()
        peak = max(peak, arm.q[0] - goal[0])
    return peak, blocked_state, abs(arm.q[0] - goal[0])


def test_anti_windup_bounds_the_integrator_of_a_blocked_joint():
    gains = PIGains()
    peak, (saturated, correction, integrator), final = _release_overshoot(3.0)
    assert saturated
    assert abs(correction) <= gains.max_correction[0] + 1e-12
    assert abs(integrator) <= gains.integrator_limit[0] + 1e-12
    assert final < 1e-5
    # Blocked for 3 s, the release overshoots no more than an unblocked step does (a wound-up
    # integrator would add up to integrator_limit = 0.15 rad).
    peak_free, _, _ = _release_overshoot(0.0)
    assert peak <= peak_free + 0.005


def test_output_is_clamped_to_joint_limits_and_integrator_holds():
    arm = LaggingArm()
    pi = PIServo(arm)
    goal = Q0.copy()
    goal[4] = JOINT_LIMITS[4, 1]  # load pulls wrist pitch back from its upper limit
    arm.load[4] = np.deg2rad(1.5)
    pi.servo_jp(goal)
    run(arm, pi, 1.0)
    assert pi.commanded[4] <= JOINT_LIMITS[4, 1]
    assert pi.integrator[4] < 0.1 * pi.gains.integrator_limit[4] + np.deg2rad(1.5)


def test_state_is_observable_and_attach_registers_the_rate():
    arm = LaggingArm()
    pi = PIServo(arm, rate=250.0)
    registered = []
    handle = pi.attach(lambda period, cb: registered.append((period, cb)) or "h")
    assert handle == "h" and registered[0][0] == pytest.approx(0.004)
    registered[0][1](0.004)
    assert pi.updates == 1 and arm.commands == 1 and pi.last_time == 0.004
    st = pi.state()
    for key in ("desired", "measured", "estimate", "error", "integrator", "commanded"):
        assert st[key].shape == (6,)
    np.testing.assert_allclose(st["desired"], Q0)  # holds where it was with no setpoint


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        PIServo(LaggingArm(), rate=0.0)
    with pytest.raises(ValueError):
        PIServo(LaggingArm()).servo_jp([0.0] * 5)
    with pytest.raises(ValueError):
        PIServo(LaggingArm()).servo_jp([np.nan] * 6)
    with pytest.raises(ValueError):
        PIGains(kp=-1.0)


class StictionArm(LaggingArm):
    """A joint that only moves while the command is more than ``band`` away (Coulomb friction)."""

    def __init__(self, band=0.026):
        super().__init__(load=np.zeros(6))
        self.band = band

    def physics_step(self):
        gap = self.cmd - self.q
        push = np.sign(gap) * np.maximum(np.abs(gap) - self.band, 0.0)
        self.q = self.q + PHYSICS_DT / self.tau * push


def _peak_stiction_error(direction_memory: bool, seconds: float, desired) -> float:
    """Peak joint-1 error after t = 2 s of the PI servo on stiction, commanded desired(t, dt)."""
    arm = StictionArm()
    # Fixed gains: this isolates the direction memory on a first-order toy plant.
    pi = PIServo(arm, gains=PIGains(direction_memory=direction_memory, adaptive=False))
    every = round(pi.dt / PHYSICS_DT)
    peak = 0.0
    for k in range(round(seconds / PHYSICS_DT)):
        t = k * PHYSICS_DT
        if k % every == 0:
            pi.servo_jp(desired(t, pi.dt))
            pi.update(t)
        arm.physics_step()
        if t > 2.0:
            peak = max(peak, abs(pi.desired[0] - arm.q[0]))
    return peak


def _reversal_error(direction_memory: bool) -> float:
    """Peak joint-1 error over the 3rd-5th periods of a back-and-forth desired motion."""

    def sine(t: float, dt: float) -> np.ndarray:
        return Q0 + np.r_[0.05 * np.sin(2 * np.pi * t), 0, 0, 0, 0, 0]

    return _peak_stiction_error(direction_memory, 5.0, sine)


def test_direction_memory_removes_most_of_the_lag_at_motion_reversals():
    with_memory, without = _reversal_error(True), _reversal_error(False)
    assert with_memory < 0.25 * without
    assert with_memory < np.deg2rad(0.2)


def _restart_error(direction_memory: bool) -> float:
    """Peak joint-1 error of the 3rd ramp of ramp-hold-ramp-hold-ramp motion on stiction."""
    q1 = [Q0[0]]

    def ramps(t: float, dt: float) -> np.ndarray:
        if (t % 1.0) < 0.5:  # 0.5 s at 0.2 rad/s, then 0.5 s of hold
            q1[0] += 0.2 * dt
        return np.r_[q1[0], Q0[1:]]

    return _peak_stiction_error(direction_memory, 3.0, ramps)


def test_motion_restarts_from_the_integrator_of_the_last_motion_not_of_the_hold():
    with_memory, without = _restart_error(True), _restart_error(False)
    assert with_memory < 0.2 * without and with_memory < np.deg2rad(0.1)


def test_followed_move_runs_at_the_loop_rate_whatever_the_callers_step():
    from suture_bt.planning import JointMove

    def run_with_chunks(chunk):
        arm = LaggingArm()
        pi = PIServo(arm)
        move = JointMove(pi, Q0 + np.array([0.2, -0.1, 0.01, 0.3, 0.2, -0.2]))
        move.start(Q0)
        pi.follow(move)
        trace, k = [], 0
        every = round(pi.dt / PHYSICS_DT)
        while k * PHYSICS_DT < move.duration + 0.5:
            for _ in range(round(chunk / PHYSICS_DT)):  # the world stepping one "tick"
                if k % every == 0:
                    pi.update(k * PHYSICS_DT)
                arm.physics_step()
                k += 1
            trace.append(arm.q.copy())
        return move, pi, np.array(trace)

    fine_move, _, fine = run_with_chunks(0.005)
    coarse_move, coarse_pi, coarse = run_with_chunks(0.05)
    assert fine_move.status.done and coarse_move.status.done and coarse_pi.source is None
    np.testing.assert_array_equal(fine[9::10][: len(coarse)], coarse[: len(fine[9::10])])
    np.testing.assert_allclose(coarse[-1], fine_move.waypoints[-1], atol=1e-5)
    with pytest.raises(ValueError, match="sink"):
        PIServo(LaggingArm()).follow(fine_move)


class ServoArm:
    """The simulator's low-level joint servo (no pybullet) behind the arm protocol."""

    def __init__(self, bandwidth_hz: float, friction_deg: float = 1.5):
        from suture_bt.sim.joint_servo import JointServo, ServoParams

        params = ServoParams(bandwidth_hz=bandwidth_hz, revolute_friction_deg=friction_deg)
        self.servo = JointServo(Q0, params)

    def measured_jp(self):
        return self.servo.q.copy()

    def servo_jp(self, q):
        self.servo.setpoint = np.asarray(q, dtype=float).copy()


def _settled_error(
    bandwidth_hz: float,
    gains: PIGains | None,
    enabled: bool = True,
    return_servo: bool = False,
    moves: int = 4,
):
    """Mean |error| of the revolute joints at the end of 0.8 s holds after ``moves`` ramps
    (rad)."""
    arm = ServoArm(bandwidth_hz)
    pi = PIServo(arm, gains=gains, enabled=enabled)
    rng = np.random.default_rng(3)
    q, errors, every = Q0.copy(), [], round(pi.dt / PHYSICS_DT)
    for _ in range(moves):
        goal = q + rng.uniform(-0.3, 0.3, 6) * np.array([1, 1, 0.05, 1, 1, 1])
        for k in range(round(1.6 / PHYSICS_DT)):
            if k % every == 0:
                s = min(1.0, k * PHYSICS_DT / 0.8)
                pi.servo_jp(q + (goal - q) * (10 * s**3 - 15 * s**4 + 6 * s**5))
                pi.update(k * PHYSICS_DT)
            arm.servo.step(PHYSICS_DT)
            if k * PHYSICS_DT > 1.5:
                errors.append(np.abs(goal - arm.servo.q)[[0, 1, 3, 4, 5]])
        q = goal
    return pi if return_servo else float(np.mean(errors))


@pytest.mark.parametrize("bandwidth_hz", [3.0, 12.0])
def test_adaptive_loop_removes_the_error_on_slow_and_fast_plants_it_is_not_told(bandwidth_hz):
    low = _settled_error(bandwidth_hz, None, enabled=False)
    adaptive = _settled_error(bandwidth_hz, None)
    assert np.rad2deg(low) > 1.0  # the low-level servo alone leaves ~1.5°
    assert adaptive < 0.05 * low  # ≥ 95 % removed
    if bandwidth_hz == 3.0:  # the fixed 6 Hz gains hunt on the slow plant
        assert adaptive < 0.5 * _settled_error(bandwidth_hz, PIGains(adaptive=False))


def test_plant_estimate_converges_to_slow_and_fast_plants_from_measured_joints_only():
    # Twelve ramps (1.6 s each): the estimate starts at the nominal 6 Hz and converges.
    for bandwidth_hz in (3.0, 6.0, 12.0):
        pi = _settled_error(bandwidth_hz, None, return_servo=True, moves=12)
        estimate = pi.estimator.bandwidth[[0, 1, 3, 4, 5]] / (2 * np.pi)
        np.testing.assert_allclose(estimate, bandwidth_hz, rtol=0.1)


def test_a_provisional_estimate_installed_to_hold_the_pose_does_not_move_the_arm():
    arm = LaggingArm(offset=DQ_B)
    pi = PIServo(arm)
    pi.reset()  # holds where it is
    run(arm, pi, 0.5)
    before = arm.q.copy()
    pi.set_offset_estimate(DQ_B, hold_pose=True)
    run(arm, pi, 0.5)
    np.testing.assert_allclose(arm.q, before, atol=1e-6)  # stayed put
    np.testing.assert_allclose(pi.estimated_jp(), arm.q, atol=1e-6)  # now reads the truth
    # Installed without holding, the same estimate moves the arm to the desired true joints.
    arm2 = LaggingArm(offset=DQ_B)
    pi2 = PIServo(arm2)
    pi2.reset()
    run(arm2, pi2, 0.5)
    desired = pi2.setpoint_jp()
    pi2.set_offset_estimate(DQ_B)
    run(arm2, pi2, 1.0)
    np.testing.assert_allclose(arm2.q, desired, atol=1e-6)
