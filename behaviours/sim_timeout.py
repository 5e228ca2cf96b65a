"""``SimTimeout``: py_trees' Timeout measured in simulated time (DESIGN.md §4).

``py_trees.decorators.Timeout`` reads ``time.monotonic()``, so a run stepped faster or slower
than real time, or paused in a debugger between ticks, times out at a different tick. This
decorator reads an injected clock (``setup(clock=...)``, anything with ``now()`` in seconds),
so the same scene and seed time out at the same tick however long each tick takes.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import py_trees
from py_trees.behaviour import Behaviour
from py_trees.common import Status


class SimTimeout(py_trees.decorators.Decorator):
    """Fail a child that is still RUNNING after ``duration`` seconds of simulated time.

    Otherwise the decorator mirrors the child's status and feedback message. On a timeout the
    child is stopped (INVALID, like py_trees' Timeout does it) and the feedback says what it
    was doing. As in py_trees' Timeout, the child is ticked first and the time checked after,
    so a child that finishes on the tick the time runs out keeps its result.
    """

    def __init__(self, name: str, child: Behaviour, duration: float):
        super().__init__(name=name, child=child)
        if not (isinstance(duration, numbers.Real) and math.isfinite(duration) and duration >= 0):
            raise ValueError(f"SimTimeout {name!r}: duration must be a finite time ≥ 0 s")
        self.duration = float(duration)
        #: Simulated time the current run started (None before the first tick).
        self.start_time: float | None = None
        self.time_source: Any = None

    def setup(self, **kwargs: Any) -> None:
        """Take ``clock`` (an object with ``now()`` in simulated seconds) from the tree's setup."""
        clock = kwargs.get("clock")
        if clock is None or not callable(getattr(clock, "now", None)):
            raise RuntimeError(
                f"SimTimeout {self.name!r} needs setup(clock=...): an object whose now() gives "
                "simulated time in seconds"
            )
        self.time_source = clock

    def _now(self) -> float:
        if self.time_source is None:
            raise RuntimeError(f"SimTimeout {self.name!r} needs setup(clock=...) before ticking")
        return float(self.time_source.now())

    @property
    def elapsed(self) -> float:
        """Simulated seconds since the current run started (0 before it started)."""
        return 0.0 if self.start_time is None else self._now() - self.start_time

    def initialise(self) -> None:
        """A new run starts now (simulated time)."""
        self.start_time = self._now()
        self.feedback_message = ""

    def update(self) -> Status:
        child = self.decorated
        if child.status == Status.RUNNING and self.elapsed > self.duration:
            doing = child.feedback_message or "no feedback"
            self.feedback_message = (
                f"timed out after {self.duration:.1f} s of simulated time; "
                f"{child.name!r} was still running: {doing}"
            )
            child.stop(Status.INVALID)
            return Status.FAILURE
        self.feedback_message = child.feedback_message
        return child.status
