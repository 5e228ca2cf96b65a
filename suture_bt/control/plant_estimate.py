"""Online estimate of each joint's low-level servo, from measured and commanded joints only.

Why: the arm's low-level servo is not the model (bandwidth, damping, friction and load differ
per robot and per joint, and the controller is never told them). The PI loop's velocity
feed-forward and integral gain depend on how slow the plant is, so the loop identifies it
while the arm moves. Per joint, a second-order servo with Coulomb friction and a slowly varying
load obeys (per unit gain)::

    u − q = a·q̈ + b·q̇ + f₊·[q̇ > 0] + f₋·[q̇ < 0]      a = 1/Kp = 1/ω², b = Kd/Kp = 2ζ/ω

where u is the command sent, q the measured joint (an encoder bias cancels: both carry it) and
f₊, f₋ the load plus or minus the Coulomb friction, one constant per direction of motion. (As
c·sign(q̇) + d the two constants cannot be told apart within one move, and each reversal's
correction leaked into b: a 6 Hz servo with 1.5° friction read as 3.2-4 Hz; per direction it
reads 6 Hz.) Recursive least squares with forgetting fits them on samples where the joint slides
(|q̇| above ``min_speed``, no reversal or stick inside the 3-sample window: static friction
breaks the model there). ``q̇`` and ``q̈`` are central differences of the measured joints, and
the command over the window is the mean of the two held commands.

With ``a = b²/4`` (critical damping, the default) the model is nonlinear in b; each update is
a Gauss-Newton step linearised at the current b (regressor ``q̇ + b·q̈/2``). Substituting the
current b² into a instead, as a fixed point, diverges whenever a joint decelerates hard
(|q̈/q̇| > 2/b): b grew to 10¹² within 0.2 s on a 6 Hz joint and the loop then scheduled itself
for a 1 Hz plant, overshooting by 5° on the next fast move. Updates that leave b outside
:data:`LAG_RANGE` or produce non-finite values are rejected and the covariance is reset.
"""

from __future__ import annotations

import numpy as np

from suture_bt.kinematics import NUM_JOINTS

#: Prior plant: the nominal 6 Hz, critically damped servo (DESIGN.md §5).
PRIOR_BANDWIDTH_HZ = 6.0
#: Bandwidths outside this band are not believed (the estimate keeps its last plausible value).
PLAUSIBLE_HZ = (1.0, 40.0)
#: Valid samples per joint before the estimate replaces the prior.
MIN_SAMPLES = 30
#: Slowest joint speed that counts as sliding (rad/s; m/s for insertion).
MIN_SPEED = np.array([0.01, 0.01, 0.0005, 0.01, 0.01, 0.01])
#: Kd/Kp (s) an update may leave: 2ζ/ω for ζ in [0.4, 2.5] over :data:`PLAUSIBLE_HZ`.
LAG_RANGE = (2 * 0.4 / (2 * np.pi * PLAUSIBLE_HZ[1]), 2 * 2.5 / (2 * np.pi * PLAUSIBLE_HZ[0]))
#: Prior covariance (also what a rejected update resets to): loose on every parameter. The
#: per-direction constants (load ± friction, up to several degrees) need the loose 0.1 rad:
#: at 0.01 rad the fit explained a 1.5° friction with lag and read a 6 Hz servo as 3-4 Hz.
PRIOR_COVARIANCE = np.diag([1e-4, 1e-2, 1e-2, 1e-2])
#: Covariance trace bound: forgetting without excitation (a hold) would inflate P without limit.
MAX_COVARIANCE_TRACE = 10 * float(np.trace(PRIOR_COVARIANCE))


class PlantEstimator:
    """Per-joint RLS of ``u − q = a·q̈ + b·q̇ + f₊·[q̇>0] + f₋·[q̇<0]``; call :meth:`observe`
    each period."""

    def __init__(
        self,
        dt: float,
        forgetting: float = 0.995,
        min_speed=MIN_SPEED,
        fit_stiffness: bool = False,
    ):
        self.dt = float(dt)
        self.fit_stiffness = fit_stiffness
        self.forgetting = float(forgetting)
        self.min_speed = np.broadcast_to(np.asarray(min_speed, dtype=float), (NUM_JOINTS,))
        w = 2 * np.pi * PRIOR_BANDWIDTH_HZ
        self.theta = np.tile([1.0 / w**2, 2.0 / w, 0.0, 0.0], (NUM_JOINTS, 1))
        # Prior covariance: loose on every parameter (the prior only fills in until data).
        self.P = np.tile(PRIOR_COVARIANCE, (NUM_JOINTS, 1, 1))
        #: Updates rejected per joint (non-finite or implausible lag), for logs and tests.
        self.rejected = np.zeros(NUM_JOINTS, dtype=int)
        self.samples = np.zeros(NUM_JOINTS, dtype=int)
        self._bandwidth = np.full(NUM_JOINTS, w)
        self._lag = np.full(NUM_JOINTS, 2.0 / w)
        self._q: list[np.ndarray] = []
        self._u: list[np.ndarray] = []

    def reset_history(self) -> None:
        """Forget the last samples (after a jump in commands, e.g. a new offset estimate)."""
        self._q.clear()
        self._u.clear()

    def observe(self, q_measured: np.ndarray, u_previous: np.ndarray | None) -> None:
        """A new measured q_k and the command u_{k−1} sent at the previous period."""
        self._q = [*self._q[-2:], np.asarray(q_measured, dtype=float).copy()]
        if u_previous is not None:
            self._u = [*self._u[-1:], np.asarray(u_previous, dtype=float).copy()]
        if len(self._q) < 3 or len(self._u) < 2:
            return
        q0, q1, q2 = self._q
        d1, d2 = q1 - q0, q2 - q1
        v = (q2 - q0) / (2 * self.dt)
        acc = (d2 - d1) / self.dt**2
        # Both half-windows sliding the same way (a joint that sticks inside one is excluded).
        step = self.min_speed * self.dt
        sliding = (np.sign(d1) == np.sign(d2)) & (np.abs(d1) > step) & (np.abs(d2) > step)
        y = 0.5 * (self._u[0] + self._u[1]) - q1
        for j in np.nonzero(sliding)[0]:
            b0 = self.theta[j, 1]
            if self.fit_stiffness:
                phi, target = np.array([acc[j], v[j], v[j] > 0, v[j] < 0], float), y[j]
            else:  # a = b²/4: Gauss-Newton in b about b0 (see the module docstring)
                phi = np.array([0.0, v[j] + 0.5 * b0 * acc[j], v[j] > 0, v[j] < 0], float)
                target = y[j] + 0.25 * b0**2 * acc[j]
            P = self.P[j]
            Pphi = P @ phi
            gain = Pphi / (self.forgetting + phi @ Pphi)
            theta = self.theta[j] + gain * (target - phi @ self.theta[j])
            P_new = (P - np.outer(gain, Pphi)) / self.forgetting
            if not (np.all(np.isfinite(theta)) and LAG_RANGE[0] <= theta[1] <= LAG_RANGE[1]):
                self.rejected[j] += 1
                self.P[j] = PRIOR_COVARIANCE.copy()
                continue
            trace = float(np.trace(P_new))
            if trace > MAX_COVARIANCE_TRACE:
                P_new *= MAX_COVARIANCE_TRACE / trace
            self.theta[j], self.P[j] = theta, P_new
            self.samples[j] += 1
            if not self.fit_stiffness:
                self.theta[j, 0] = 0.25 * self.theta[j, 1] ** 2
            self._refresh(j)

    def _refresh(self, j: int) -> None:
        a, b = self.theta[j, 0], self.theta[j, 1]
        if self.samples[j] < MIN_SAMPLES or a <= 0 or b <= 0:
            return
        w = 1.0 / np.sqrt(a)
        if PLAUSIBLE_HZ[0] <= w / (2 * np.pi) <= PLAUSIBLE_HZ[1] and b * w < 6.0:
            self._bandwidth[j], self._lag[j] = w, b

    @property
    def bandwidth(self) -> np.ndarray:
        """Estimated natural frequency ω per joint (rad/s); the prior until enough samples."""
        return self._bandwidth.copy()

    @property
    def lag(self) -> np.ndarray:
        """Estimated Kd/Kp (s) per joint: how far a ramp lags per unit speed."""
        return self._lag.copy()

    @property
    def inverse_stiffness(self) -> np.ndarray:
        """1/ω² (s²) per joint: how far the servo lags per unit acceleration."""
        return 1.0 / self._bandwidth**2
