"""A stand-in trial for testing the runner in milliseconds: same spec in, same payload out.

``spec["fake"]`` picks the behaviour: ``pass`` / ``fail`` (a result whose throws passed or
not), ``raise`` (an exception), ``exit`` (``os._exit(3)``: the process dies), ``segv`` (a real
segmentation fault), ``hang`` (sleeps past any time budget). ``sleep`` adds a delay.
The synthetic tip trajectory of a passing fake crosses Entry1 and then Exit1 of two synthetic
port frames, so the trajectory scorer and the report see real crossings.
"""

from __future__ import annotations

import ctypes
import json
import os
import time
from typing import Any

import numpy as np

#: Synthetic port frames: Entry1 at the origin (z up), Exit1 4 mm along +x (z up).
FAKE_PORTS = {
    "Entry1": {"p": [0.0, 0.0, 0.0], "R": np.eye(3).tolist()},
    "Exit1": {"p": [0.004, 0.0, 0.0], "R": np.eye(3).tolist()},
}


def fake_trajectory(passed: bool) -> str:
    """A tip that goes down through Entry1 and up through Exit1 (or stops short of it)."""
    rows, t = [], 0.0
    path = [(0.0, 0.0, 0.003), (0.0, 0.0, -0.002), (0.004, 0.0, -0.002)]
    path.append((0.004, 0.0, 0.008) if passed else (0.004, 0.0, -0.001))
    for a, b in zip(path[:-1], path[1:], strict=True):
        for s in np.linspace(0.0, 1.0, 20, endpoint=False):
            p = np.add(a, s * np.subtract(b, a))
            rows.append(f"{t:.6f},{p[0]:.9f},{p[1]:.9f},{p[2]:.9f}")
            t += 0.01
    rows.append(f"{t:.6f},{path[-1][0]:.9f},{path[-1][1]:.9f},{path[-1][2]:.9f}")
    return "t,tip_x,tip_y,tip_z\n" + "\n".join(rows) + "\n"


def fake_trial(
    spec: dict[str, Any], plan: dict[int, str] | None = None, sleep: float = 0.0
) -> dict[str, Any]:
    """Behave as ``plan[index]`` (else ``spec["fake"]``, else ``pass``) says (see the module
    docstring); bind ``plan`` with ``functools.partial`` to script a whole campaign."""
    mode = (plan or {}).get(spec["index"], spec.get("fake", "pass"))
    time.sleep(float(spec.get("sleep", sleep)))
    if mode == "raise":
        raise RuntimeError(f"fake trial {spec['index']} raised")
    if mode == "exit":
        os._exit(3)
    if mode == "segv":
        ctypes.string_at(0)  # reads address 0: SIGSEGV
    if mode == "hang":
        time.sleep(3600)
    passed = mode == "pass"
    throw = {
        "pair": 1,
        "passed": passed,
        "entry_lateral_mm": 0.0,
        "exit_lateral_mm": 0.0 if passed else None,
        "tip_out_mm": 8.0 if passed else None,
        "strain_mm": 0.1,
        "stab_mm": None,
        "sim_time_s": 1.0 + spec["seed"] % 5,
        "failure": None if passed else "no exit crossing of exit1 after entry1",
    }
    result = {
        "passed": passed,
        "sim_time_s": throw["sim_time_s"],
        "wall_time_s": 0.5,
        "seed": spec["seed"],
        "oracle": False,
        "tree": spec.get("tree", "multi_throw"),
        "error": None,
        "throws": [throw],
        "calibration_error": {"psm1": [0.1, -0.1, 0.05]},
        "ports": FAKE_PORTS,
    }
    files = {"result.json": json.dumps(result), "trajectory.csv": fake_trajectory(passed)}
    extras = {
        "fake": mode,
        "scene": spec["scene"],
        "throw_windows": {"1": [0.0, throw["sim_time_s"]]},
        # odd trials: a slip inside the throw, and a lost frame after it
        "faults_fired": [
            {"kind": "slip", "t": 0.5, "arm": "psm2"},
            {"kind": "frame_lost", "t": 99.0, "arm": None},
        ]
        if spec["index"] % 2
        else [],
    }
    return {"status": "ok", "files": files, "extras": extras}
