"""The skill protocol: a generator program stepped tick by tick, failures, checks, nesting, stop."""

from types import SimpleNamespace

import pytest

from suture_bt.skills.base import Skill, SkillFailure, SkillStatus

RUNNING, SUCCESS, FAILURE = SkillStatus.RUNNING, SkillStatus.SUCCESS, SkillStatus.FAILURE


class FakeClock:
    def __init__(self, t: float = 0.0):
        self.t = t

    def now(self) -> float:
        return self.t


class FakeServo:
    def __init__(self):
        self.stops = 0

    def stop_following(self) -> None:
        self.stops += 1


def make_context(arms=None):
    return SimpleNamespace(clock=FakeClock(10.0), arms={} if arms is None else arms)


def tick(skill: Skill, dt: float = 0.05) -> SkillStatus:
    """Advance the fake clock by dt, then step the skill."""
    skill.context.clock.t += dt
    return skill.step(dt)


class Twice(Skill):
    """Yields twice, then returns; counts runs of its ``finally``."""

    name = "twice"

    def __init__(self, context, fail_with: str | None = None):
        super().__init__(context)
        self.fail_with = fail_with
        self.entered = 0
        self.finalised = 0
        self.dts = []

    def program(self):
        self.entered += 1
        try:
            self.say("first wait")
            yield
            self.dts.append(self.dt)
            self.say("second wait")
            yield
            self.dts.append(self.dt)
            if self.fail_with is not None:
                raise SkillFailure(self.fail_with)
        finally:
            self.finalised += 1


class Silent(Skill):
    name = "silent"

    def program(self):
        yield


class Raises(Skill):
    name = "raises"

    def program(self):
        yield
        raise SkillFailure("x")


class Checks(Skill):
    name = "checks"

    def __init__(self, context, second_ok: bool):
        super().__init__(context)
        self.second_ok = second_ok
        self.after = False

    def program(self):
        self.check("first", True, "all good")
        yield
        self.check("second", self.second_ok, "3.2 mm off")
        self.after = True


class Parent(Skill):
    name = "parent"

    def __init__(self, context, sub: Skill):
        super().__init__(context)
        self.sub = sub
        self.got = None
        self.after = False

    def program(self):
        self.say("before the sub-skill")
        yield
        self.got = yield from self.run(self.sub)
        self.after = True


def test_yields_twice_then_succeeds():
    s = Twice(make_context())
    s.start()
    assert s.status is RUNNING and s.feedback == "starting"
    assert s.report["t_start"] == 10.0 and s.report["skill"] == "twice"
    assert [tick(s), tick(s), tick(s)] == [RUNNING, RUNNING, SUCCESS]
    assert s.report["t_end"] == pytest.approx(10.15)
    assert s.report["status"] == "SUCCESS"
    assert s.report["checks"] == []
    assert s.dts == [0.05, 0.05]
    assert s.finalised == 1
    # Further steps keep the outcome and do not re-run anything.
    assert tick(s) is SUCCESS and s.entered == 1


def test_success_without_feedback_says_done():
    s = Silent(make_context())
    s.start()
    assert [tick(s), tick(s)] == [RUNNING, SUCCESS]
    assert s.feedback == "done"


def test_success_keeps_last_feedback():
    s = Twice(make_context())
    s.start()
    while tick(s) is RUNNING:
        pass
    assert s.feedback == "second wait"


def test_skill_failure_gives_failure_with_reason():
    s = Raises(make_context())
    s.start()
    assert [tick(s), tick(s)] == [RUNNING, FAILURE]
    assert s.feedback == "x"
    assert s.report["failure"] == "x"
    assert s.report["status"] == "FAILURE"
    assert s.report["t_end"] == pytest.approx(10.1)
    assert tick(s) is FAILURE


def test_failure_after_yields_runs_finally():
    s = Twice(make_context(), fail_with="wire slipped")
    s.start()
    assert [tick(s), tick(s), tick(s)] == [RUNNING, RUNNING, FAILURE]
    assert s.feedback == "wire slipped" and s.finalised == 1


def test_passing_check_is_recorded_and_failing_one_fails():
    s = Checks(make_context(), second_ok=False)
    s.start()
    assert tick(s) is RUNNING
    assert s.report["checks"] == [{"check": "first", "ok": True, "detail": "all good"}]
    assert tick(s) is FAILURE
    assert s.report["checks"][-1] == {"check": "second", "ok": False, "detail": "3.2 mm off"}
    assert s.feedback == "second: 3.2 mm off"
    assert s.report["failure"] == "second: 3.2 mm off"
    assert s.after is False  # nothing after a failed check runs


def test_all_checks_passing_succeeds():
    s = Checks(make_context(), second_ok=True)
    s.start()
    assert [tick(s), tick(s)] == [RUNNING, SUCCESS]
    assert [c["ok"] for c in s.report["checks"]] == [True, True]
    assert s.after is True


def test_check_coerces_ok_to_bool():
    s = Checks(make_context(), second_ok=True)
    s.start()
    s.check("numpy-ish", 1, "truthy")
    assert s.report["checks"][-1]["ok"] is True
    with pytest.raises(SkillFailure, match="zero: falsy"):
        s.check("zero", 0, "falsy")


def test_run_nests_a_sub_skill():
    ctx = make_context()
    sub = Twice(ctx)
    p = Parent(ctx, sub)
    p.start()
    statuses = [tick(p, 0.02) for _ in range(4)]
    # tick 1: parent waits; ticks 2-3: sub waits; tick 4: sub ends, parent ends.
    assert statuses == [RUNNING, RUNNING, RUNNING, SUCCESS]
    assert p.got is sub and p.after is True
    assert sub.status is SUCCESS and sub.dts == [0.02, 0.02]
    assert p.report["steps"] == [sub.report]
    assert sub.report["status"] == "SUCCESS"
    assert p.report["status"] == "SUCCESS"


def test_run_shows_sub_feedback_while_it_runs():
    ctx = make_context()
    p = Parent(ctx, Twice(ctx))
    p.start()
    tick(p)
    assert p.feedback == "before the sub-skill"
    tick(p)
    assert p.feedback == "first wait"
    tick(p)
    assert p.feedback == "second wait"


def test_run_carries_the_sub_failure():
    ctx = make_context()
    sub = Twice(ctx, fail_with="needle not seen")
    p = Parent(ctx, sub)
    p.start()
    statuses = [tick(p) for _ in range(4)]
    assert statuses == [RUNNING, RUNNING, RUNNING, FAILURE]
    assert p.feedback == "needle not seen"
    assert p.report["failure"] == "needle not seen"
    assert p.report["steps"][0]["failure"] == "needle not seen"
    assert p.after is False


def test_stop_mid_program_closes_the_generator_and_restart_is_clean():
    ctx = make_context()
    s = Twice(ctx)
    s.start()
    assert tick(s) is RUNNING
    first_report = s.report
    s.stop()
    assert s.finalised == 1  # the program's finally ran
    assert s.status is FAILURE
    assert tick(s) is FAILURE and s.entered == 1  # nothing resumes a stopped program
    ctx.clock.t = 20.0
    s.start()
    assert s.status is RUNNING and s.report is not first_report
    assert s.report["t_start"] == 20.0 and "t_end" not in s.report
    assert [tick(s), tick(s), tick(s)] == [RUNNING, RUNNING, SUCCESS]
    assert s.entered == 2 and s.finalised == 2


def test_start_while_running_restarts():
    s = Twice(make_context())
    s.start()
    tick(s)
    s.start()
    assert s.finalised == 1  # the abandoned program was closed
    assert [tick(s), tick(s), tick(s)] == [RUNNING, RUNNING, SUCCESS]


def test_stop_after_success_keeps_success():
    s = Silent(make_context())
    s.start()
    tick(s)
    tick(s)
    s.stop()
    assert s.status is SUCCESS


def test_arms_are_held_on_failure_and_stop_not_on_success():
    servos = {n: FakeServo() for n in ("psm1", "psm2")}
    ctx = make_context({n: SimpleNamespace(servo=sv) for n, sv in servos.items()})
    ok = Silent(ctx)
    ok.start()
    tick(ok)
    tick(ok)
    assert [sv.stops for sv in servos.values()] == [0, 0]
    bad = Raises(ctx)
    bad.start()
    tick(bad)
    tick(bad)
    assert [sv.stops for sv in servos.values()] == [1, 1]
    stopped = Twice(ctx)
    stopped.start()
    tick(stopped)
    stopped.stop()
    assert [sv.stops for sv in servos.values()] == [2, 2]


def test_stop_mid_sub_skill_stops_the_sub_skill():
    ctx = make_context()
    sub = Twice(ctx)
    p = Parent(ctx, sub)
    p.start()
    tick(p)
    tick(p)
    assert sub.status is RUNNING
    p.stop()
    assert sub.finalised == 1
    assert sub.status is not RUNNING
