"""Simulated time in whole physics ticks, and the callbacks due every so many of them.

The world's single loop (DESIGN.md §4) advances :class:`SimClock` one tick at a time and,
first thing in each tick, runs the :class:`PeriodicCallbacks` due then (the high-level servo,
recorders), so their rates are exact multiples of the physics step and never drift.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


class SimClock:
    """Simulated time, counted in whole physics ticks (no drift)."""

    def __init__(self, dt: float):
        self.dt = dt
        self.ticks = 0

    def now(self) -> float:
        return self.ticks * self.dt


@dataclass
class _Periodic:
    period_ticks: int
    next_tick: int
    callback: Callable[[float], None]


class PeriodicCallbacks:
    """Callbacks run every whole number of ticks of ``clock``, in registration order."""

    def __init__(self, clock: SimClock):
        self.clock = clock
        self._entries: list[_Periodic] = []

    def add(self, period: float, callback: Callable[[float], None]) -> object:
        """Call ``callback(t)`` every ``period`` s of simulated time, from the next tick on;
        ``period`` must be a whole number of ticks. Returns the handle :meth:`remove` takes."""
        ticks = period / self.clock.dt
        if not np.isfinite(ticks) or ticks < 0.999 or abs(ticks - round(ticks)) > 1e-6:
            raise ValueError(
                f"period {period!r} s is not a positive multiple of the physics step "
                f"{self.clock.dt} s"
            )
        handle = _Periodic(int(round(ticks)), self.clock.ticks + 1, callback)
        self._entries.append(handle)
        return handle

    def remove(self, handle: object) -> None:
        """Stop a periodic callback (unknown handles are an error)."""
        try:
            self._entries.remove(handle)
        except ValueError:
            raise ValueError("remove_periodic: unknown handle") from None

    def run_due(self, tick: int, t: float) -> None:
        """Run the callbacks due at ``tick`` (time ``t``); one removed by an earlier callback
        in the same tick does not run."""
        for p in list(self._entries):
            if tick >= p.next_tick and p in self._entries:
                p.next_tick += p.period_ticks
                p.callback(t)
