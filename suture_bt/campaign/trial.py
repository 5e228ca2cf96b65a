"""One campaign trial in a worker: build the drawn scene, run the tree, return its files.

Runs wherever the backend puts it (a local child process or a Ray worker) and returns a plain
payload, never writing to the campaign directory itself, so both backends record trials the
same way: ``{"status": "ok", "files": {name: text or bytes}, "extras": {...}}`` (``run.rrd``,
with ``rerun = "save"``, is bytes).

Per-tick bookkeeping (:class:`TrialMonitor`, front door: ground truth only through
:class:`~suture_bt.sim.ground_truth.GroundTruth`):

* the SRC Task 1 score of every localisation: the vision sensor's estimate against the true
  needle pose at the frame's time stamp (sum of base + mid + tip point distances, plus the
  arc-centre and rotation errors), and whether the tree adopted it as its belief by the end of
  the tick (a skill's check may reject an answer). One estimate per tick is seen: a second
  ``observe`` in the same tick would hide the first (the skills call it at most once a tick);
* recoveries by kind: each time a ``RecoveryNode``'s recovery child runs, counted under the
  node's name;
* wall-clock time per throw, from the throw windows the tree writes.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

#: Trial spec keys (built by :func:`suture_bt.campaign.runner.trial_specs`).
SPEC_KEYS = ("index", "seed", "scene", "tree", "oracle", "policy", "max_sim_time", "rerun")


def single_thread() -> None:
    """One compute thread per trial: trials run side by side, and a fixed thread count keeps
    results identical whichever backend (and however many cores) runs them."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import cv2

    from suture_bt.compute_threads import set_compute_threads

    set_compute_threads(1)  # torch's and numba's (numba's pool would undo torch's alone)
    cv2.setNumThreads(1)


def _rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices (degrees)."""
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


class TrialMonitor:
    """Called after every tick (``Session.run(on_tick=...)``): Task 1 scores, recoveries,
    wall time per throw."""

    def __init__(self, session: Any) -> None:
        """Cache the truth the first tick's frame will be compared with."""
        from suture_bt.behaviours.recovery import RecoveryNode
        from suture_bt.sim.ground_truth import GroundTruth

        self.session = session
        self.truth = GroundTruth(session.world)
        self.localisations: list[dict[str, Any]] = []
        self.refusals = 0
        self.recoveries: dict[str, int] = {}
        self._recovery_nodes = [n for n in session.root.iterate() if isinstance(n, RecoveryNode)]
        self._seen = {id(n): 0 for n in self._recovery_nodes}
        self._calls = int(getattr(session.context.sensor, "calls", 0))
        self._last_estimate = None
        self._throw_wall: dict[int, list[float | None]] = {}
        self._t0 = time.perf_counter()
        self._cache_truth()

    def _cache_truth(self) -> None:
        """True needle pose now: what a frame captured during the next tick shows."""
        self._truth_t = float(self.session.context.clock.now())
        self._truth_T = np.array(self.truth.needle_pose(), dtype=float)

    def __call__(self, session: Any) -> None:
        """After one tick: look at the sensor, the recovery nodes and the throw windows."""
        self._localisation()
        self._count_recoveries()
        self._throw_walls()
        self._cache_truth()

    def _localisation(self) -> None:
        sensor = self.session.context.sensor
        calls = int(getattr(sensor, "calls", 0))
        if calls == self._calls:
            return
        self._calls = calls
        est = getattr(sensor, "last_estimate", None)
        if est is None:
            self.refusals += 1
            return
        if est is self._last_estimate:
            return
        self._last_estimate = est
        frame = getattr(sensor, "last_frame", None)
        stamp = float(frame.stamp) if frame is not None else float("nan")
        needle = self.session.context.needle
        T_est, T_true = np.asarray(est.T_world_needle, dtype=float), self._truth_T
        got, true = needle.scored_points(T_est), needle.scored_points(T_true)
        errs = {k: 1e3 * float(np.linalg.norm(got[k] - true[k])) for k in true}
        belief = self.session.context.belief
        adopted = belief is not None and np.allclose(belief.T_world_needle, T_est, atol=1e-9)
        self.localisations.append(
            {
                "t": round(stamp, 4),
                "adopted": bool(adopted),
                "stamp_matches_truth": bool(abs(stamp - self._truth_t) < 1e-6),
                "task1_score_mm": round(sum(errs.values()), 4),
                **{f"{k}_mm": round(v, 4) for k, v in errs.items()},
                "centre_mm": round(1e3 * float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3])), 4),
                "angle_deg": round(_rotation_deg(T_est[:3, :3], T_true[:3, :3]), 4),
            }
        )

    def _count_recoveries(self) -> None:
        for node in self._recovery_nodes:
            seen = self._seen[id(node)]
            if len(node.history) < seen:  # the node started afresh
                seen = 0
            for _, child, _, _ in node.history[seen:]:
                if child == node.recovery.name:
                    self.recoveries[node.name] = self.recoveries.get(node.name, 0) + 1
            self._seen[id(node)] = len(node.history)

    def _throw_walls(self) -> None:
        now = time.perf_counter() - self._t0
        for pair, rec in self.session.context.throws.items():
            start_end = self._throw_wall.setdefault(int(pair), [now, None])
            if rec.get("t_end") is not None and start_end[1] is None:
                start_end[1] = now

    def extras(self) -> dict[str, Any]:
        """What the trial adds to ``result.json`` (JSON-ready)."""
        throws = self.session.context.throws
        return {
            "localisations": self.localisations,
            "localisation_refusals": self.refusals,
            "recoveries": dict(sorted(self.recoveries.items())),
            "recovery_nodes": len(self._recovery_nodes),
            "throw_windows": {
                str(p): [r.get("t_start"), r.get("t_end")] for p, r in sorted(throws.items())
            },
            "faults_fired": [
                {"kind": e.kind, "t": round(float(e.time), 4), "arm": e.arm}
                for e in self.truth.fault_events()
                if e.kind != "servo_model"  # the drawn servo is a parameter, not an event
            ],
            "throw_wall_s": {
                str(p): None if w[1] is None else round(w[1] - w[0], 3)
                for p, w in sorted(self._throw_wall.items())
            },
        }


def run_trial(spec: dict[str, Any]) -> dict[str, Any]:
    """Run one trial (see the module docstring); exceptions propagate to the backend's guard."""
    single_thread()
    from suture_bt.runtime.session import RunOptions, Session
    from suture_bt.sim.scene import scene_from_dict

    t0, cpu0 = time.perf_counter(), time.process_time()
    scene = scene_from_dict(spec["scene"])
    options = RunOptions(
        tree=spec["tree"],
        scene="scene.yaml",  # a label: the trial's scene file, written next to result.json
        seed=int(spec["seed"]),
        oracle=bool(spec["oracle"]),
        policy=spec["policy"],
        max_sim_time=float(spec["max_sim_time"]),
    )
    session = Session(options, scene)
    with tempfile.TemporaryDirectory() as tmp:
        try:
            if spec.get("rerun", "off") == "save":
                from suture_bt.runtime.recording import attach_recording

                attach_recording(session, "save", Path(tmp) / "run.rrd", say=lambda _: None)
            monitor = TrialMonitor(session)
            try:
                session.run(monitor)
            except KeyboardInterrupt:
                session.error = "interrupted"
            session.write(Path(tmp))
            extras = monitor.extras()
        finally:
            session.close()  # also closes the recording's sinks
        files: dict[str, str | bytes] = {
            n: (Path(tmp) / n).read_text() for n in ("result.json", "trajectory.csv")
        }
        if (Path(tmp) / "run.rrd").is_file():
            files["run.rrd"] = (Path(tmp) / "run.rrd").read_bytes()
    files["scene.yaml"] = scene_yaml(spec["scene"])
    extras["trial_wall_s"] = round(time.perf_counter() - t0, 3)
    # CPU seconds of the trial: what it costs on an idle core, however loaded the machine is.
    extras["trial_cpu_s"] = round(time.process_time() - cpu0, 3)
    return {"status": "ok", "files": files, "extras": extras}


def scene_yaml(scene: dict[str, Any]) -> str:
    """The trial's scene as a file ``suture-bt run --scene`` accepts (replays the trial)."""
    head = "# A campaign trial's scene: suture-bt run --scene scene.yaml replays it.\n"
    return head + yaml.safe_dump(scene, sort_keys=False)
