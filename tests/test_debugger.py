"""The tick-by-tick debugger: commands, breakpoints, the observer, the Python stepping API,
``suture-bt debug`` scripted (bad input; a whole single throw that must equal the undebugged
run) and in a real terminal (tmux)."""

import io
import shutil
import subprocess
import sys
import time

import pytest
from py_trees.common import Status
from recording_helpers import SEED, TREE, fake_session, recorded_run, result_without_wall_time

from suture_bt.cli import main
from suture_bt.runtime.debugger import CommandError, Debugger, parse, parse_script
from suture_bt.runtime.observer import Sink


def _debugger(session):
    out, ended = io.StringIO(), []
    return Debugger(session, out=out, on_end=lambda: ended.append(session.ticks)), out, ended


# ---------------------------------------------------------------------- commands
def test_parse_commands_aliases_and_errors():
    assert parse("  s 5  ").name == "step" and parse("s 5").arg == "5"
    assert parse("c").name == "continue" and parse("q").name == "quit"
    assert parse("# a comment") is None and parse("   ") is None
    assert parse("break Insert pair 1=failure").arg == "Insert pair 1=failure"
    assert parse("node Needle in PSM2's hand?").arg == "Needle in PSM2's hand?"
    for bad, fragment in [
        ("stpe", "unknown command 'stpe'"),
        ("step 0", "positive number"),
        ("step two", "positive number"),
        ("break", "needs a node name"),
        ("break Insert=DONE", "unknown status 'DONE'"),
        ("tree now", "takes no argument"),
    ]:
        with pytest.raises(CommandError, match=fragment):
            parse(bad)
    with pytest.raises(CommandError, match="cmds.txt line 3: unknown command 'frob'"):
        parse_script(["step", "", "frob", "quit"], "cmds.txt")


def test_breakpoints_stepping_until_fail_and_the_end():
    session = fake_session()
    dbg, out, ended = _debugger(session)
    dbg.run_script(parse_script(["break insert pair 1", "continue", "node Insert"], "t"))
    text = out.getvalue()
    assert "stopped after tick 2 (0.04 s): breakpoint insert pair 1=RUNNING" in text
    assert "Insert pair 1: INVALID → RUNNING" in text
    assert "tick 2 (0.02 s) RUNNING" in text  # the node's history
    assert ended == [2]  # the script ended (EOF = quit) before the run
    assert session.error.startswith("stopped in the debugger at tick 2")

    session = fake_session()
    dbg, out, ended = _debugger(session)
    dbg.execute(parse("until-fail"))
    text = out.getvalue()
    assert "stopped after tick 4 (0.08 s): a failure" in text
    assert "Insert pair 1: RUNNING → FAILURE -- jaw empty" in text
    dbg.execute(parse("step"))  # the tree failed in the same tick: the run has ended
    assert "the run ended at tick 4 (0.08 s): FAILURE" in out.getvalue()
    assert ended == [4]
    dbg.execute(parse("tree"))
    assert "Insert pair 1 [✕] -- jaw empty" in out.getvalue()
    assert dbg.execute(parse("quit")) is False and ended == [4] and session.error is None


def test_step_prints_transitions_and_unknown_nodes_are_refused():
    session = fake_session()
    dbg, out, _ = _debugger(session)
    dbg.execute(parse("step 2"))
    assert "tick 2 (0.02 s) Approach: RUNNING → SUCCESS -- working" in out.getvalue()
    assert "now: Insert pair 1" in out.getvalue()
    dbg.execute(parse("break Extract"))
    assert "error: no node named 'Extract'" in out.getvalue()
    with pytest.raises(CommandError, match="no node named 'Extract'"):
        dbg.check(parse_script(["break Extract=SUCCESS"], "f"), "f")


def test_observer_fans_out_to_sinks_and_drops_a_broken_one():
    class Count(Sink):
        def __init__(self):
            self.changes, self.ticks = [], 0

        def status_changed(self, change):
            self.changes.append((change.tick, change.node.name, change.status))

        def tick(self, session, record):
            self.ticks += 1

    class Broken(Sink):
        def tick(self, session, record):
            raise RuntimeError("disk full")

    session = fake_session()
    good = session.observer.add(Count())
    session.observer.add(Broken())
    while not session.finished:
        session.tick()
    assert good.ticks == 4 and (1, "Approach", Status.RUNNING) in good.changes
    assert (4, "Root", Status.FAILURE) in good.changes
    assert len(session.observer.sinks) == 1
    assert "Broken.tick failed and was dropped: disk full" in session.observer.warnings[0]


# ---------------------------------------------------------------------- the real session
def test_python_stepping_api_on_the_localize_tree():
    from suture_bt.runtime.session import Session

    session = Session(tree="localize", seed=SEED)
    try:
        record = session.step()
        assert record.tick == 1 and session.ticks == 1
        assert "Localize needle in PSM2 [*]" in session.tree_text()
        hit = session.run_until("Localize needle in PSM2=SUCCESS")
        assert hit is not None and hit.changes[0].node.name == "Localize needle in PSM2"
        assert "Localize needle in PSM2 [✓]" in session.tree_text()
        assert session.run_until("until-fail") is None and session.finished
    finally:
        session.close()


def _one_error_line(capsys, *args):
    code = main(list(args))
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1, err
    return err[0]


@pytest.mark.parametrize(
    "lines, fragment",
    [
        (["break Insert pair 1", "stepp"], "line 2: unknown command 'stepp'"),
        (["step -1"], "line 1: step takes a positive number"),
        (["break Insert pair 1=DONE"], "line 1: unknown status 'DONE'"),
    ],
)
def test_malformed_commands_file_is_one_line_and_nonzero(tmp_path, capsys, lines, fragment):
    f = tmp_path / "cmds.txt"
    f.write_text("\n".join(lines) + "\n")
    line = _one_error_line(
        capsys, "debug", "localize", "--commands", str(f), "--out", str(tmp_path)
    )
    assert fragment in line and not (tmp_path / "result.json").exists()


def test_debug_bad_input(tmp_path, capsys):
    missing = str(tmp_path / "none.txt")
    assert "no such file" in _one_error_line(capsys, "debug", "localize", "--commands", missing)
    assert "unknown tree 'sideways'" in _one_error_line(capsys, "debug", "sideways")
    # A breakpoint on a node the tree does not have: refused before anything ticks.
    f = tmp_path / "cmds.txt"
    f.write_text("break Insert pair 1\ncontinue\n")
    args = ["debug", "localize", "--rerun", "off", "--commands", str(f), "--out", str(tmp_path)]
    assert "no node named 'Insert pair 1'" in _one_error_line(capsys, *args)
    assert not (tmp_path / "result.json").exists()


@pytest.mark.slow
def test_debugged_single_throw_equals_the_undebugged_run(tmp_path, capsys):
    reference = recorded_run()
    cmds = tmp_path / "cmds.txt"
    cmds.write_text("break Insert pair 1\ncontinue\nstep\ntree\nbb\nworld\ncontinue\nquit\n")
    out = tmp_path / "debug"
    code = main(["debug", TREE, "--seed", str(SEED), "--commands", str(cmds), "--out", str(out)])
    text = capsys.readouterr().out
    assert "breakpoint 1: Insert pair 1=RUNNING" in text
    assert "stopped after tick" in text and "Insert pair 1: INVALID → RUNNING" in text
    assert "Insert pair 1 [*]" in text  # the tree, after one more step
    assert "Blackboard Data" in text and "/arms/psm2/calibrated" in text
    assert "the run ended at tick" in text and "results:" in text
    assert "needle estimate:" in text and "GROUND TRUTH" not in text
    ours = result_without_wall_time(out / "result.json")
    assert ours == result_without_wall_time(reference / "result.json")
    assert code == (0 if ours["passed"] else 1)
    assert (out / "run.rrd").stat().st_size > 0


# ---------------------------------------------------------------------- a real terminal
@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed")
def test_debugger_in_a_real_terminal(tmp_path):
    name = f"suture-bt-test-{time.monotonic_ns()}"
    exe = f"{sys.executable} -m suture_bt.cli"
    command = f"{exe} debug localize --rerun off --out {tmp_path}"
    subprocess.run(["tmux", "new-session", "-d", "-s", name, "-x", "200", "-y", "60", command],
                   check=True)  # fmt: skip

    def screen():
        return subprocess.run(
            ["tmux", "capture-pane", "-p", "-t", name, "-S", "-200"],
            capture_output=True, text=True, check=False,
        ).stdout  # fmt: skip

    def wait_for(text, timeout=90.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if text in screen():
                return screen()
            time.sleep(0.3)
        raise AssertionError(f"{text!r} never appeared:\n{screen()}")

    def send(line):
        subprocess.run(["tmux", "send-keys", "-t", name, line, "Enter"], check=True)

    try:
        wait_for("(debug #0 0.00s)")
        send("break Localize needle in PSM2=SUCCESS")
        wait_for("breakpoint 1:")
        send("c")
        wait_for("breakpoint Localize needle in PSM2=SUCCESS")
        send("tree")
        text = wait_for("Localize needle in PSM2 [✓]")
        assert "Localize the needle" in text
        send("quit")
        wait_for("results:")
    finally:
        subprocess.run(["tmux", "kill-session", "-t", name], check=False, capture_output=True)
