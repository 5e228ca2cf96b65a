"""One run of a suture tree in a simulated world: build, tick, score, write.

The single-threaded loop of DESIGN.md §4: every tick the tree is ticked once (behaviours step
their skills, which command motions) and then the world advances by ``tick_dt`` of simulated
time (the PI servos and physics run inside at their own rates). Pausing between ticks changes
nothing. After the run, every throw is scored from the world's own records (ground truth:
port crossings, tissue entries, strain) over the throw's window, never from the tree's beliefs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import py_trees

from suture_bt import trees
from suture_bt.evaluation.records import records_from_world
from suture_bt.evaluation.throw_scores import run_passed
from suture_bt.evaluation.tip_recorder import TipRecorder
from suture_bt.runtime.breakpoints import Hit, Stop, run_until
from suture_bt.runtime.camera_tap import CameraTap
from suture_bt.runtime.context_factory import build_context
from suture_bt.runtime.observer import TickRecord, TreeObserver
from suture_bt.runtime.results import result_document, write_result
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.quiet import quiet_fd
from suture_bt.sim.scene import SceneConfig, load_scene, scene_from_dict
from suture_bt.sim.world import World

#: Simulated time per tick (s): 50 Hz, the rate at which skills decide.
TICK_DT = 0.02
#: A run is stopped after this much simulated time (s), whatever the tree is doing.
MAX_SIM_TIME = 300.0
#: ``suture-bt run``'s default scene: the embedded SRC scene at the SRC Task 3 start.
TASK3_START = {"needle": {"start": "in_psm2_jaw"}}


@dataclass
class RunOptions:
    """What ``suture-bt run`` was asked to do."""

    tree: str = "multi_throw"
    scene: str | None = None
    seed: int | None = None
    oracle: bool = False
    policy: str = "stop"
    tick_dt: float = TICK_DT
    max_sim_time: float = MAX_SIM_TIME


def run_scene(options: RunOptions) -> SceneConfig:
    """The scene file (or the Task 3 start), with ``seed`` overriding the file's."""
    scene = load_scene(options.scene) if options.scene else scene_from_dict(TASK3_START)
    if options.seed is not None:
        scene = dataclasses.replace(scene, seed=int(options.seed))
    return scene


@contextlib.contextmanager
def quiet_renderer():
    """pybullet's EGL plugin prints banners (``ven = Mesa/X.org``) on both descriptors."""
    with quiet_fd(1), quiet_fd(2):
        yield


class Session:
    """A world, its context and a set-up tree, ready to tick.

    ``Session(options)`` or, in a notebook, ``Session(tree="localize", scene="s.yaml",
    seed=3)``; then ``step()``, ``run_until("Insert pair 1")``, ``tree_text()``. Every tick
    is observed (:attr:`observer`); sinks such as the rerun recording attach to it.
    """

    def __init__(
        self,
        options: RunOptions | None = None,
        scene: SceneConfig | str | Path | dict | None = None,
        **option_fields: Any,
    ):
        if options is not None and option_fields:
            raise TypeError("pass either RunOptions or option keywords, not both")
        options = options or RunOptions(**option_fields)
        if isinstance(scene, str | Path):  # a scene file: loaded like --scene (seed applies)
            options, scene = dataclasses.replace(options, scene=str(scene)), None
        elif isinstance(scene, dict):
            scene = scene_from_dict(scene)
        self.options = options
        self.scene = scene or run_scene(options)
        py_trees.blackboard.Blackboard.clear()  # one run per process state
        self.root = trees.create(options.tree, policy=options.policy)
        with quiet_renderer():
            self.world = World.from_scene(self.scene)
        self.context = build_context(self.world, oracle=options.oracle)
        self.context.camera = CameraTap(self.context.camera)  # the recording sees its frames
        self.tree = py_trees.trees.BehaviourTree(self.root)
        self.recorder = TipRecorder(self.world)
        self.error: str | None = None
        self.ticks = 0
        self.wall_time = 0.0
        with quiet_renderer():
            self.tree.setup(context=self.context, clock=self.context.clock, tick_dt=options.tick_dt)
        self.observer = TreeObserver(self.tree, self.context.clock, self)

    # ---------------------------------------------------------------- ticking
    @property
    def finished(self) -> bool:
        return (
            self.error is not None
            or self.root.status in (py_trees.common.Status.SUCCESS, py_trees.common.Status.FAILURE)
            or self.context.clock.now() >= self.options.max_sim_time
        )

    def tick(self) -> None:
        """One tick: the tree, then ``tick_dt`` of simulated time."""
        t0 = time.perf_counter()
        try:
            with quiet_renderer():
                self.tree.tick()
                self.world.step(self.options.tick_dt)
        except Exception as exc:  # noqa: BLE001 - a crash ends the run with its reason
            self.error = f"internal error at t={self.context.clock.now():.2f} s: {exc}"
            self.observer.error(self.error)
        self.ticks += 1
        self.wall_time += time.perf_counter() - t0

    def run(self, on_tick=None) -> None:
        """Tick until the tree ends, it errs, or the time limit; ``on_tick(session)`` after each."""
        while not self.finished:
            self.tick()
            if on_tick is not None:
                on_tick(self)

    def step(self, n: int = 1) -> TickRecord | None:
        """Tick up to ``n`` times (fewer when the run ends); the last tick's record."""
        for _ in range(int(n)):
            if self.finished:
                break
            self.tick()
        return self.observer.last

    def run_until(self, stop: Stop, max_ticks: int | None = None) -> Hit | None:
        """Tick until ``stop`` hits (a breakpoint such as ``"Insert pair 1"`` or
        ``"Calibrate PSM1=SUCCESS"``, ``"until-fail"``, a predicate on the session, or a
        list); the Hit, or None when the run ended first."""
        return run_until(self, stop, max_ticks)

    def tree_text(self) -> str:
        """py_trees' unicode tree with every node's status and feedback message."""
        return py_trees.display.unicode_tree(self.root, show_status=True)

    def current(self) -> str:
        """Name and feedback of the deepest running behaviour."""
        tip = self.root.tip()
        if tip is None:
            return ""
        return f"{tip.name}: {tip.feedback_message}" if tip.feedback_message else tip.name

    # ---------------------------------------------------------------- results
    def scores(self):
        pairs = tuple(sorted(self.context.throws)) or ()
        windows = {
            p: (r["t_start"], r["t_end"] if r["t_end"] is not None else self.context.clock.now())
            for p, r in self.context.throws.items()
        }
        expected = self._expected_pairs()
        return records_from_world(GroundTruth(self.world)).score(
            windows | {p: None for p in expected if p not in windows}, expected or pairs
        )

    def _expected_pairs(self) -> tuple[int, ...]:
        from suture_bt.behaviours.throw_scope import ThrowScope

        return tuple(n.pair for n in self.root.iterate() if isinstance(n, ThrowScope))

    def result(self) -> dict[str, Any]:
        """The run's ``result.json`` document (see :mod:`suture_bt.runtime.results`)."""
        scores = self.scores()
        truth = GroundTruth(self.world)
        calibration = {}
        for name, arm in self.context.arms.items():
            if arm.offset_estimate is not None:
                err = np.asarray(arm.offset_estimate) - truth.joint_offset(name)[:3]
                calibration[name] = [
                    float(np.rad2deg(err[0])),
                    float(np.rad2deg(err[1])),
                    float(1e3 * err[2]),
                ]
        # A tree without throws (calibrate, localize) passes when it ends in SUCCESS.
        passed = (
            run_passed(scores)
            if scores
            else self.error is None and self.root.status is py_trees.common.Status.SUCCESS
        )
        return result_document(self, scores, calibration, passed=passed)

    def write(self, out: Path) -> dict[str, Any]:
        """Write ``result.json`` and ``trajectory.csv`` into ``out``; returns the result."""
        result = self.result()
        out.mkdir(parents=True, exist_ok=True)
        write_result(out / "result.json", result)
        self.recorder.write_csv(out / "trajectory.csv")
        self.observer.finish(result)
        return result

    def close(self) -> None:
        """Close the observer's sinks (the recording is flushed), then the world."""
        self.observer.close()
        with quiet_renderer():
            self.world.close()
