"""The tick-by-tick debugger behind ``suture-bt debug``: commands over a :class:`Session`.

Commands (one a line; ``#`` starts a comment): ``step [N]``, ``continue``, ``break NODE``,
``break NODE=STATUS``, ``breaks``, ``delete [NODE|all]``, ``until-fail``, ``tree``, ``bb``,
``node NAME``, ``world``, ``help``, ``quit``. Interactive at a terminal (``readline`` line
editing and history), or scripted from a file or stdin. Stepping only decides *when* the next
tick runs, never what it does: the same seed gives the same run, paused or not.
"""

from __future__ import annotations

import re
import signal
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import py_trees

from suture_bt.runtime.breakpoints import Breakpoint, BreakpointError, Hit, resolve, run_until
from suture_bt.runtime.breakpoints import split_spec as split_breakpoint
from suture_bt.runtime.debug_text import change_line, changes_text, node_text, world_text
from suture_bt.runtime.observer import Sink, StatusChange, TickRecord

HELP = """commands:
  step [N]            tick once (or N times; stops early at a breakpoint)     alias s
  continue            tick until a breakpoint hits or the run ends           alias c
  break NODE          stop when NODE becomes RUNNING                          alias b
  break NODE=STATUS   stop when NODE becomes STATUS (RUNNING SUCCESS FAILURE INVALID)
  breaks              list the breakpoints;  delete [NODE|all]  remove them
  until-fail          tick until a behaviour fails (with its reason) or the run ends
  tree                the tree with every node's status and feedback message
  bb                  the blackboard, and its activity since the last stop
  node NAME           a node's status history, last feedback and skill report
  world               arm joints, calibration estimates, the needle estimate
  help                this text
  quit                end the session (the results are written)               alias q"""

COMMANDS = (
    "step", "continue", "break", "breaks", "delete", "until-fail",
    "tree", "bb", "node", "world", "help", "quit",
)  # fmt: skip
ALIASES = {"s": "step", "c": "continue", "b": "break", "q": "quit", "exit": "quit", "?": "help"}
NO_ARGUMENT = {"continue", "breaks", "until-fail", "tree", "bb", "world", "help", "quit"}
#: History of the interactive prompt (best effort).
HISTORY_FILE = Path.home() / ".suture_bt_debug_history"


class CommandError(ValueError):
    """A command line the debugger does not understand."""


@dataclass(frozen=True)
class Command:
    """One parsed command: its name, the rest of the line, and where it came from."""

    name: str
    arg: str = ""
    text: str = ""


def parse(line: str) -> Command | None:
    """The command on ``line`` (None for a blank or comment line); raises CommandError.

    ``#`` at the start of a line or after a space starts a comment."""
    text = re.split(r"(?:^|\s)#", line, maxsplit=1)[0].strip()
    if not text:
        return None
    word, _, rest = text.partition(" ")
    name, rest = ALIASES.get(word.lower(), word.lower()), rest.strip()
    if name not in COMMANDS:
        raise CommandError(f"unknown command {word!r} (try 'help')")
    if name in NO_ARGUMENT and rest:
        raise CommandError(f"'{name}' takes no argument, got {rest!r}")
    if name == "step" and rest and not (rest.isdigit() and int(rest) > 0):
        raise CommandError(f"step takes a positive number of ticks, got {rest!r}")
    if name in ("break", "node") and not rest:
        raise CommandError(f"'{name}' needs a node name: {name} NODE")
    if name == "break":
        try:
            split_breakpoint(rest)
        except BreakpointError as exc:
            raise CommandError(str(exc)) from None
    return Command(name, rest, text)


def parse_script(lines: Iterable[str], source: str) -> list[Command]:
    """Every command of a script; raises CommandError naming ``source`` and the line."""
    commands = []
    for number, line in enumerate(lines, start=1):
        try:
            cmd = parse(line)
        except CommandError as exc:
            raise CommandError(f"{source} line {number}: {exc}") from None
        if cmd is not None:
            commands.append(cmd)
    return commands


class _Since(Sink):
    """Transitions and blackboard activity since the debugger last stopped."""

    def __init__(self) -> None:
        self.changes: list[StatusChange] = []
        self.activity: list[Any] = []

    def tick(self, session: Any, record: TickRecord) -> None:
        self.changes += record.changes
        self.activity = (self.activity + list(record.activity))[-300:]


class Debugger:
    """Commands over one session, printed to ``out`` (default stdout); ``on_end()`` is called
    once, when the run ends or on quit."""

    def __init__(
        self,
        session: Any,
        out: TextIO | None = None,
        on_end: Callable[[], None] | None = None,
        truth: Any = None,
    ):
        self.session, self.out, self.on_end, self.truth = session, out, on_end, truth
        self.breakpoints: list[Breakpoint] = []
        self.since = session.observer.add(_Since())
        self.activity: list[Any] = []
        self.ended = False
        self._interrupted = False

    # ---------------------------------------------------------------- i/o
    def say(self, text: str) -> None:
        out = self.out or sys.stdout  # looked up now: stdout may have been replaced
        out.write(text.rstrip("\n") + "\n")
        out.flush()

    def prompt(self) -> str:
        s = self.session
        return f"(debug #{s.ticks} {s.context.clock.now():.2f}s) "

    # ---------------------------------------------------------------- driving
    def check(self, commands: list[Command], source: str) -> None:
        """Resolve every breakpoint of a script before anything ticks; raises CommandError."""
        for cmd in commands:
            target = split_breakpoint(cmd.arg)[0] if cmd.name == "break" else cmd.arg
            if cmd.name in ("break", "node") and not self.session.observer.find(target):
                raise CommandError(f"{source}: {cmd.text!r}: no node named {target!r}")

    def run_script(self, commands: list[Command], echo: bool = True) -> None:
        """Run the commands in order (each echoed after the prompt); EOF means quit."""
        for cmd in commands:
            if echo:
                self.say(self.prompt() + cmd.text)
            if not self.execute(cmd):
                return
        self.execute(Command("quit", text="quit"))

    def interactive(self, read: Callable[[str], str] = input) -> None:
        """Prompt until ``quit`` or end of input, with readline editing and history."""
        try:
            import readline

            readline.set_history_length(1000)
            if HISTORY_FILE.exists():
                readline.read_history_file(HISTORY_FILE)
        except (ImportError, OSError):
            readline = None  # type: ignore[assignment]
        self.say("suture-bt debugger: 'help' lists the commands")
        try:
            while True:
                try:
                    line = read(self.prompt())
                except EOFError:
                    self.say("")
                    line = "quit"
                except KeyboardInterrupt:
                    self.say("")
                    continue
                try:
                    cmd = parse(line)
                except CommandError as exc:
                    self.say(f"error: {exc}")
                    continue
                if cmd is not None and not self.execute(cmd):
                    return
        finally:
            if readline is not None:
                try:
                    readline.write_history_file(HISTORY_FILE)
                except OSError:
                    pass

    def execute(self, cmd: Command) -> bool:
        """Carry out one command; False once the session is over."""
        handler = getattr(self, "_do_" + cmd.name.replace("-", "_"))
        try:
            return handler(cmd.arg) is not False
        except BreakpointError as exc:
            self.say(f"error: {exc}")
            return True

    # ---------------------------------------------------------------- stepping
    def _advance(self, stops: list[Any], max_ticks: int | None) -> None:
        if self.session.finished:
            self._ended()
            return
        self._interrupted = False
        old = None
        try:
            old = signal.signal(signal.SIGINT, self._on_interrupt)
        except ValueError:  # not the main thread
            pass
        try:
            hit = run_until(self.session, [*stops, self._was_interrupted], max_ticks)
        finally:
            if old is not None:
                signal.signal(signal.SIGINT, old)
        self._report(hit)

    def _on_interrupt(self, *_: Any) -> None:
        self._interrupted = True

    def _was_interrupted(self, session: Any) -> bool:
        return self._interrupted

    def _report(self, hit: Hit | None) -> None:
        changes, self.since.changes = self.since.changes, []
        self.activity, self.since.activity = self.since.activity, []
        s = self.session
        where = f"tick {s.ticks} ({s.context.clock.now():.2f} s)"
        if hit is not None and hit.reason.startswith("_was_interrupted"):
            self.say(f"paused at {where} (interrupted)")
        elif hit is not None:
            self.say(f"stopped after {where}: {hit.reason}")
            for c in hit.changes:
                self.say(f"  {change_line(c)}")
            return
        else:
            self.say(changes_text(changes))
        if s.finished:
            self._ended()
        else:
            self.say(f"now: {s.current() or '-'}")

    def _ended(self) -> None:
        s = self.session
        if not self.ended:
            verdict = s.root.status.name if s.error is None else f"error: {s.error}"
            self.say(f"the run ended at tick {s.ticks} ({s.context.clock.now():.2f} s): {verdict}")
            self.ended = True
            if self.on_end is not None:
                self.on_end()
        else:
            self.say("the run has ended; 'quit' to leave")

    def _do_step(self, arg: str) -> None:
        self._advance(self.breakpoints, int(arg) if arg else 1)

    def _do_continue(self, arg: str) -> None:
        self._advance(self.breakpoints, None)

    def _do_until_fail(self, arg: str) -> None:
        self._advance([*self.breakpoints, "until-fail"], None)

    # ---------------------------------------------------------------- breakpoints
    def _do_break(self, arg: str) -> None:
        bp = resolve(arg, self.session.observer)
        self.breakpoints.append(bp)
        self.say(f"breakpoint {len(self.breakpoints)}: {bp.text} ({len(bp.ids)} node(s))")

    def _do_breaks(self, arg: str) -> None:
        if not self.breakpoints:
            self.say("no breakpoints")
        for i, bp in enumerate(self.breakpoints, start=1):
            self.say(f"breakpoint {i}: {bp.text}")

    def _do_delete(self, arg: str) -> None:
        keep = [] if arg in ("", "all") else [b for b in self.breakpoints if b.node != arg]
        self.say(f"deleted {len(self.breakpoints) - len(keep)} breakpoint(s)")
        self.breakpoints = keep

    # ---------------------------------------------------------------- looking
    def _do_tree(self, arg: str) -> None:
        self.say(self.session.tree_text())

    def _do_bb(self, arg: str) -> None:
        self.say(py_trees.display.unicode_blackboard())
        if self.activity or self.since.activity:
            items = self.activity + self.since.activity
            self.say(py_trees.display.unicode_blackboard_activity_stream(activity_stream=items))
        else:
            self.say("Blackboard Activity Stream\n    (no activity since the last stop)")

    def _do_node(self, arg: str) -> None:
        nodes = self.session.observer.find(arg)
        if not nodes:
            self.say(f"error: no node named {arg!r} (see 'tree')")
            return
        self.say(node_text(self.session.observer, nodes))

    def _do_world(self, arg: str) -> None:
        self.say(world_text(self.session, self.truth))

    def _do_help(self, arg: str) -> None:
        self.say(HELP)

    def _do_quit(self, arg: str) -> bool:
        s = self.session
        if not s.finished:
            s.error = f"stopped in the debugger at tick {s.ticks} (t={s.context.clock.now():.2f} s)"
        if not self.ended:
            self.ended = True
            if self.on_end is not None:
                self.on_end()
        return False
