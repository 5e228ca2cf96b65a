"""One recorded single-throw run per test process, shared by the debugger, recording and
inspect tests (a whole run costs tens of seconds: it is made once, on first use), and a
scripted tree in a fake session for the fast tests."""

from __future__ import annotations

import atexit
import functools
import json
import shutil
import tempfile
from pathlib import Path
from types import SimpleNamespace

import py_trees
from py_trees.common import Status

from suture_bt.cli import main
from suture_bt.runtime.observer import TreeObserver

#: The seed of the shared run (the debugger test repeats it under the debugger).
SEED = 0
TREE = "single_throw"


@functools.cache
def recorded_run() -> Path:
    """``suture-bt run single_throw --seed 0 --out DIR`` (rerun saved); DIR."""
    out = Path(tempfile.mkdtemp(prefix="suture-bt-recorded-"))
    atexit.register(shutil.rmtree, out, True)
    main(["run", TREE, "--seed", str(SEED), "--out", str(out)])
    assert (out / "result.json").exists() and (out / "run.rrd").exists()
    return out


def result_without_wall_time(path: Path) -> dict:
    """A result.json without the only field that may differ between equal runs."""
    result = json.loads(path.read_text())
    result.pop("wall_time_s")
    return result


class Scripted(py_trees.behaviour.Behaviour):
    """Returns ``statuses`` one per tick (then the last again); a FAILURE says ``reason``."""

    def __init__(self, name, statuses, reason=""):
        super().__init__(name)
        self.statuses, self.reason = list(statuses), reason

    def update(self):
        status = self.statuses.pop(0) if len(self.statuses) > 1 else self.statuses[0]
        self.feedback_message = self.reason if status == Status.FAILURE else "working"
        return status


class FakeSession:
    """The parts of a Session the debugger and the tree sink use, over scripted behaviours."""

    def __init__(self, root):
        self.root, self.ticks, self.error, self.now = root, 0, None, 0.0
        self.context = SimpleNamespace(clock=SimpleNamespace(now=lambda: self.now))
        self.options = SimpleNamespace(
            tree="scripted", scene=None, oracle=False, policy="stop", tick_dt=0.02
        )
        self.scene = SimpleNamespace(seed=7)
        self.tree = py_trees.trees.BehaviourTree(root)
        self.tree.setup()
        self.observer = TreeObserver(self.tree, self.context.clock, self)

    @property
    def finished(self):
        return self.root.status in (Status.SUCCESS, Status.FAILURE)

    def tick(self):
        self.tree.tick()
        self.now += 0.02
        self.ticks += 1

    def current(self):
        tip = self.root.tip()
        return tip.name if tip else ""

    def tree_text(self):
        return py_trees.display.unicode_tree(self.root, show_status=True)


def fake_session() -> FakeSession:
    """Root sequence: Approach (RUNNING, SUCCESS), then Insert pair 1 (RUNNING ×2, FAILURE
    "jaw empty"): the tree fails at tick 4."""
    R, S, F = Status.RUNNING, Status.SUCCESS, Status.FAILURE
    root = py_trees.composites.Sequence(
        "Root",
        memory=True,
        children=[Scripted("Approach", [R, S]), Scripted("Insert pair 1", [R, R, F], "jaw empty")],
    )
    return FakeSession(root)


class Looking(py_trees.behaviour.Behaviour):
    """A skill's behaviour whose looks are refused on ticks 1 and 3 (in a finished sub-skill's
    report on tick 3, whose failure the skill's own list quotes, as an in-hand check's does),
    then found on tick 4."""

    def __init__(self):
        super().__init__("Localize needle")
        self.skill = SimpleNamespace(report={"checks": []})
        self.n = 0

    def update(self):
        self.n += 1
        report = self.skill.report
        if self.n == 1:
            report.setdefault("refusals", []).append("needle out of view")
        if self.n == 3:
            report["steps"] = [{"checks": [], "refusals": ["two views disagree: 4 mm"]}]
            report["refusals"] += ["valley 1.01x", "look 2 failed: two views disagree: 4 mm"]
        return Status.SUCCESS if self.n == 4 else Status.RUNNING


def looking_session() -> FakeSession:
    """Root sequence of one :class:`Looking` skill: refused looks on ticks 1 and 3, found on 4."""
    return FakeSession(py_trees.composites.Sequence("Root", memory=True, children=[Looking()]))


def record_scripted(session: FakeSession, path: Path, result: dict | None = None) -> Path:
    """Tick a scripted ``session`` to its end with the tree sink saving to ``path`` (an .rrd),
    then finish it with ``result`` (if given) and close it; ``path``."""
    import rerun as rr

    from suture_bt.recording.tree_sink import Flush, TreeSink

    rec = rr.RecordingStream("suture-bt-test", recording_id=path.stem)
    rec.save(path)
    for sink in (TreeSink(rec), Flush(rec)):
        session.observer.add(sink)
    while not session.finished:
        session.tick()
    if result is not None:
        session.observer.finish(result)
    session.observer.close()
    return path
