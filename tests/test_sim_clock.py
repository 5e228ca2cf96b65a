"""Simulated time and the periodic callbacks the world runs first in each physics tick."""

import pytest

from suture_bt.sim.sim_clock import PeriodicCallbacks, SimClock


def _run(clock: SimClock, callbacks: PeriodicCallbacks, ticks: int) -> None:
    for _ in range(ticks):
        clock.ticks += 1
        callbacks.run_due(clock.ticks, clock.now())


def test_the_clock_counts_whole_ticks_without_drift():
    clock = SimClock(0.001)
    clock.ticks = 1_000_000
    assert clock.now() == pytest.approx(1000.0, abs=1e-9)


def test_callbacks_run_at_their_period_from_the_next_tick_in_registration_order():
    clock = SimClock(0.001)
    clock.ticks = 7
    callbacks, calls = PeriodicCallbacks(clock), []
    callbacks.add(0.002, lambda t: calls.append(("a", round(t / clock.dt))))
    callbacks.add(0.001, lambda t: calls.append(("b", round(t / clock.dt))))
    _run(clock, callbacks, 4)
    assert calls == [("a", 8), ("b", 8), ("b", 9), ("a", 10), ("b", 10), ("b", 11)]


def test_a_callback_removed_by_an_earlier_one_in_the_same_tick_does_not_run():
    clock = SimClock(0.001)
    callbacks, calls = PeriodicCallbacks(clock), []
    to_remove = []

    def remove_the_second(t: float) -> None:
        while to_remove:
            callbacks.remove(to_remove.pop())

    callbacks.add(0.001, remove_the_second)
    second = callbacks.add(0.001, lambda t: calls.append(t))
    to_remove.append(second)
    _run(clock, callbacks, 3)
    assert calls == []
    with pytest.raises(ValueError, match="unknown handle"):
        callbacks.remove(second)


@pytest.mark.parametrize("period", [0.0, -0.001, 0.0015, float("nan"), float("inf")])
def test_a_period_not_a_whole_number_of_ticks_is_refused(period):
    with pytest.raises(ValueError, match="not a positive multiple"):
        PeriodicCallbacks(SimClock(0.001)).add(period, lambda t: None)
