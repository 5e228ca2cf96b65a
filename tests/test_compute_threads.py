"""One thread count for torch and numba: numba's first parallel call does not undo torch's."""

import subprocess
import sys
from pathlib import Path

import pytest

from suture_bt.compute_threads import set_compute_threads

_CHILD = """
import sys
import torch
from suture_bt.compute_threads import set_compute_threads
{setup}
sys.path.insert(0, {tests!r})
from perception_helpers import MODEL, poses_near_the_needle
from suture_bt.perception.edge_kernel import edge_normal_equations
from suture_bt.perception.fit_solver import FD_STEPS
rays, T, T6 = poses_near_the_needle()
torch.get_num_threads()  # torch's pool is up, as once the localiser's network has run
edge_normal_equations(T, T6, FD_STEPS, rays, MODEL, 1.0, "cauchy")  # numba's parallel loop
print(torch.get_num_threads())
"""


def _torch_threads_after_a_numba_parallel_call(setup: str) -> int:
    """torch's thread count in a fresh process after ``setup`` and one numba parallel call
    (a fresh process: numba's pool starts once per process)."""
    code = _CHILD.format(setup=setup, tests=str(Path(__file__).parent))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1])


def test_torch_keeps_the_count_set_with_numba_and_not_torch_alone():
    import numba

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: numba's pool cannot raise torch's count")
    assert _torch_threads_after_a_numba_parallel_call("set_compute_threads(1)") == 1
    # The trap it avoids: torch's own setting, undone by numba's first parallel call.
    assert _torch_threads_after_a_numba_parallel_call("torch.set_num_threads(1)") > 1


def test_a_count_below_one_is_refused():
    with pytest.raises(ValueError, match="at least 1"):
        set_compute_threads(0)
