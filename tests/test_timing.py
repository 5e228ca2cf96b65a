"""Time-scaling profiles: boundary values, monotonicity and the velocity/acceleration limits."""

import numpy as np
import pytest

from suture_bt.planning.timing import (
    MinJerkProfile,
    TrapezoidalProfile,
    make_profile,
    normalised_limits,
)


def _sample(prof, n=4001):
    t = np.linspace(0.0, prof.duration, n)
    s = np.array([prof.s(x) for x in t])
    return t, s


@pytest.mark.parametrize("cls", [TrapezoidalProfile, MinJerkProfile])
@pytest.mark.parametrize("v,a", [(0.5, 2.0), (3.0, 1.0), (0.1, 100.0)])
def test_profile_runs_zero_to_one_within_limits(cls, v, a):
    prof = cls(v, a)
    t, s = _sample(prof)
    assert s[0] == pytest.approx(0.0, abs=1e-12) and s[-1] == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.diff(s) >= -1e-12)
    ds = np.array([prof.ds(x) for x in t])
    dds = np.array([prof.dds(x) for x in t])
    assert ds.max() <= v * (1 + 1e-9) and dds.max() <= a * (1 + 1e-9)
    assert -dds.min() <= a * (1 + 1e-9)
    # The analytic derivative matches the numerical one.
    num = np.gradient(s, t)
    np.testing.assert_allclose(ds[5:-5], num[5:-5], atol=1e-3 * max(ds.max(), 1))


def test_trapezoid_reaches_cruise_or_is_a_triangle():
    long_move = TrapezoidalProfile(0.5, 2.0)  # v²/a = 0.125 < 1: cruises at v
    assert long_move.v_peak == pytest.approx(0.5)
    assert long_move.duration == pytest.approx(0.25 + 2.0)
    short = TrapezoidalProfile(5.0, 1.0)  # triangle: peak sqrt(a·1) = 1
    assert short.v_peak == pytest.approx(1.0)
    assert short.duration == pytest.approx(2.0)


def test_min_jerk_is_time_optimal_for_its_shape():
    # The binding limit is met with equality.
    prof = MinJerkProfile(0.5, 100.0)
    t, _ = _sample(prof)
    assert max(prof.ds(x) for x in t) == pytest.approx(0.5, rel=1e-3)


def test_multi_coordinate_limits_hold_for_every_coordinate():
    dist = np.array([0.3, -1.2, 0.0, 0.05])
    v = np.array([0.6, 0.6, 0.6, 0.05])
    a = np.array([2.0, 2.0, 2.0, 0.2])
    prof = make_profile("trapezoidal", dist, v, a)
    t = np.linspace(0, prof.duration, 2001)
    vel = np.abs(np.outer([prof.ds(x) for x in t], dist))
    acc = np.abs(np.outer([prof.dds(x) for x in t], dist))
    assert np.all(vel <= v * (1 + 1e-9)) and np.all(acc <= a * (1 + 1e-9))
    # Joint 2 (largest distance/limit ratio) binds.
    assert vel[:, 1].max() == pytest.approx(0.6, rel=1e-6)


def test_zero_move_is_done_at_once_and_bad_input_is_refused():
    prof = make_profile("min_jerk", [0.0, 0.0], [1.0, 1.0], [1.0, 1.0])
    assert prof.duration == 0.0 and prof.s(0.0) == 1.0
    assert normalised_limits([0.0], 1.0, 1.0) == (np.inf, np.inf)
    with pytest.raises(ValueError, match="unknown profile"):
        make_profile("cubic", [1.0], 1.0, 1.0)
    with pytest.raises(ValueError, match="positive"):
        TrapezoidalProfile(0.0, 1.0)
    with pytest.raises(ValueError, match="positive"):
        normalised_limits([1.0], -1.0, 1.0)
