"""The skill protocol: ``start()``, ``step(dt) -> SkillStatus``, ``feedback``, ``report``.

A skill is a task-level action that never blocks a tick: its body is a generator
(:meth:`Skill.program`) that yields while it waits (for a motion, the jaw, a settle time) and
raises :class:`SkillFailure` with a one-line reason when a step or a check fails. ``step``
advances it by one tick of simulated time. ``report`` keeps what the skill planned and saw
(poses, estimates, checks) for logs and the rerun recording; ``feedback`` is one line.
"""

from __future__ import annotations

import enum
from collections.abc import Generator
from typing import Any

#: What a skill's program yields while it waits (nothing: it is only resumed next tick).
Waiting = Generator[None, None, Any]


class SkillStatus(enum.Enum):
    """The outcome of one step (mirrors py_trees' RUNNING / SUCCESS / FAILURE)."""

    RUNNING = "RUNNING"
    SUCCESS = "SUCCESS"
    FAILURE = "FAILURE"


class SkillFailure(Exception):
    """A step or check of a skill failed; ``reason`` is one line for the user."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class Skill:
    """Base class: subclasses implement :meth:`program` (a generator) and set ``name``."""

    name = "skill"
    #: Arms whose motions this skill commands (None: any); an abandoned or failed program
    #: holds only these, so a skill running beside another one leaves that one's arm alone.
    arms: tuple[str, ...] | None = None

    def __init__(self, context):
        self.context = context
        self.status = SkillStatus.RUNNING
        self.feedback = ""
        self.report: dict[str, Any] = {}
        self._program: Generator | None = None
        self._sub: Skill | None = None
        self.dt = 0.0

    # ---------------------------------------------------------------- protocol
    def start(self) -> None:
        """Begin (or begin again): a fresh program, a fresh report."""
        self.stop()
        self.status = SkillStatus.RUNNING
        self.feedback = "starting"
        self.report = {"skill": self.name, "t_start": self.context.clock.now(), "checks": []}
        self._program = self.program()

    def step(self, dt: float) -> SkillStatus:
        """Advance the program by one tick of ``dt`` simulated seconds."""
        if self._program is None:
            return self.status
        self.dt = dt
        try:
            next(self._program)
        except StopIteration:
            self._finish(SkillStatus.SUCCESS)
        except SkillFailure as failure:
            self.feedback = failure.reason
            self.report["failure"] = failure.reason
            self._finish(SkillStatus.FAILURE)
        return self.status

    def stop(self) -> None:
        """Abandon a running program (pre-emption): motions in progress are held."""
        if self._sub is not None:
            self._sub.stop()
            self._sub = None
        if self._program is not None:
            self._program.close()
            self._program = None
            self.status = SkillStatus.FAILURE if self.status is SkillStatus.RUNNING else self.status
            self.on_stop()

    # ---------------------------------------------------------------- for subclasses
    def program(self) -> Waiting:
        """The skill's body; yield to wait a tick, raise SkillFailure to fail."""
        raise NotImplementedError

    def on_stop(self) -> None:
        """Called when a program is abandoned or ends: an unfinished motion is held where it is."""
        if self.status is not SkillStatus.SUCCESS:
            for name, arm in self.context.arms.items():
                if self.arms is None or name in self.arms:
                    arm.servo.stop_following()

    def run(self, sub: Skill) -> Waiting:
        """Run another skill inside this one's program (its report is kept in ours)."""
        sub.start()
        self._sub = sub
        while True:
            status = sub.step(self.dt)
            self.feedback = sub.feedback
            if status is SkillStatus.RUNNING:
                yield
                continue
            self._sub = None
            self.report.setdefault("steps", []).append(sub.report)
            if status is SkillStatus.FAILURE:
                raise SkillFailure(sub.feedback)
            return sub

    def say(self, text: str) -> None:
        """Set the one-line feedback (what the skill is doing now)."""
        self.feedback = text

    def check(self, name: str, ok: bool, detail: str) -> None:
        """Record a confirmation in the report; a failed one fails the skill with its detail."""
        self.report["checks"].append({"check": name, "ok": bool(ok), "detail": detail})
        if not ok:
            raise SkillFailure(f"{name}: {detail}")

    def _finish(self, status: SkillStatus) -> None:
        self.status = status
        self.report["t_end"] = self.context.clock.now()
        self.report["status"] = status.value
        if status is SkillStatus.SUCCESS and self.feedback in ("", "starting"):
            self.feedback = "done"
        self._program = None
        self.on_stop()
