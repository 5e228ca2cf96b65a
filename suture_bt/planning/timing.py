"""Time-scaling profiles s(t) ∈ [0, 1] for point-to-point moves under velocity/acceleration limits.

A move of several coordinates (joints, or position and angle) shares one normalised profile,
so every coordinate starts and stops together. The limits on s follow from the coordinates'
limits and distances: ṡ ≤ min_i v_i / |Δ_i| and s̈ ≤ min_i a_i / |Δ_i|.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

#: Peak velocity and acceleration of the quintic s = 10τ³ − 15τ⁴ + 6τ⁵ over unit duration.
MIN_JERK_PEAK_VEL = 1.875
MIN_JERK_PEAK_ACC = 10.0 / np.sqrt(3.0)


class Profile(Protocol):
    """A normalised time scaling: s(0) = 0, s(duration) = 1, monotone."""

    duration: float

    def s(self, t: float) -> float: ...
    def ds(self, t: float) -> float: ...
    def dds(self, t: float) -> float: ...


def _check_limits(v_max: float, a_max: float) -> None:
    if not (np.isfinite(v_max) and np.isfinite(a_max)) or v_max <= 0 or a_max <= 0:
        raise ValueError(f"limits must be positive and finite, got v={v_max}, a={a_max}")


@dataclass(frozen=True)
class TrapezoidalProfile:
    """Accelerate at a_max, cruise at v_max, decelerate (a triangle when v_max is not reached)."""

    v_max: float
    a_max: float

    def __post_init__(self):
        _check_limits(self.v_max, self.a_max)

    @property
    def v_peak(self) -> float:
        return float(min(self.v_max, np.sqrt(self.a_max)))

    @property
    def t_acc(self) -> float:
        return self.v_peak / self.a_max

    @property
    def duration(self) -> float:
        # Distance 1 = v_peak · (t_acc + t_cruise).
        return self.t_acc + 1.0 / self.v_peak

    def s(self, t: float) -> float:
        T, ta, vp, a = self.duration, self.t_acc, self.v_peak, self.a_max
        t = min(max(t, 0.0), T)
        if t < ta:
            return 0.5 * a * t * t
        if t <= T - ta:
            return 0.5 * a * ta * ta + vp * (t - ta)
        r = T - t
        return 1.0 - 0.5 * a * r * r

    def ds(self, t: float) -> float:
        T, ta = self.duration, self.t_acc
        if t <= 0.0 or t >= T:
            return 0.0
        return self.a_max * min(t, ta, T - t)

    def dds(self, t: float) -> float:
        T, ta = self.duration, self.t_acc
        if t <= 0.0 or t >= T:
            return 0.0
        if t < ta:
            return self.a_max
        if t > T - ta:
            return -self.a_max
        return 0.0


@dataclass(frozen=True)
class MinJerkProfile:
    """Quintic minimum-jerk scaling, stretched until both peaks are within the limits."""

    v_max: float
    a_max: float

    def __post_init__(self):
        _check_limits(self.v_max, self.a_max)

    @property
    def duration(self) -> float:
        return float(max(MIN_JERK_PEAK_VEL / self.v_max, np.sqrt(MIN_JERK_PEAK_ACC / self.a_max)))

    def _tau(self, t: float) -> float:
        return min(max(t / self.duration, 0.0), 1.0)

    def s(self, t: float) -> float:
        x = self._tau(t)
        return x**3 * (10.0 - 15.0 * x + 6.0 * x * x)

    def ds(self, t: float) -> float:
        x = self._tau(t)
        return 30.0 * x * x * (1.0 - x) ** 2 / self.duration

    def dds(self, t: float) -> float:
        x = self._tau(t)
        return 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / self.duration**2


PROFILES = {"trapezoidal": TrapezoidalProfile, "min_jerk": MinJerkProfile}


def normalised_limits(distances, v_max, a_max) -> tuple[float, float]:
    """Limits on ṡ and s̈ so that every coordinate i stays within v_max[i] and a_max[i].

    Coordinates that do not move impose nothing; when none moves both limits are infinite.
    """
    d = np.abs(np.atleast_1d(np.asarray(distances, dtype=float)))
    v = np.broadcast_to(np.asarray(v_max, dtype=float), d.shape)
    a = np.broadcast_to(np.asarray(a_max, dtype=float), d.shape)
    if np.any(v <= 0) or np.any(a <= 0):
        raise ValueError("velocity and acceleration limits must be positive")
    moving = d > 1e-15
    if not np.any(moving):
        return np.inf, np.inf
    return float(np.min(v[moving] / d[moving])), float(np.min(a[moving] / d[moving]))


@dataclass(frozen=True)
class StillProfile:
    """A zero-length move: done at once."""

    duration: float = 0.0

    def s(self, t: float) -> float:
        return 1.0

    def ds(self, t: float) -> float:
        return 0.0

    def dds(self, t: float) -> float:
        return 0.0


def make_profile(kind: str, distances, v_max, a_max) -> Profile:
    """Profile of ``kind`` ("trapezoidal" or "min_jerk") for coordinates moving ``distances``."""
    if kind not in PROFILES:
        raise ValueError(f"unknown profile {kind!r}; choose one of {sorted(PROFILES)}")
    vs, as_ = normalised_limits(distances, v_max, a_max)
    if not np.isfinite(vs):
        return StillProfile()
    return PROFILES[kind](vs, as_)
