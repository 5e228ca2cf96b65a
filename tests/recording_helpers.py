"""One recorded single-throw run per test process, shared by the debugger, recording and
inspect tests (a whole run costs tens of seconds: it is made once, on first use)."""

from __future__ import annotations

import atexit
import functools
import json
import shutil
import tempfile
from pathlib import Path

from suture_bt.cli import main

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
