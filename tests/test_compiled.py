"""The localiser's compiled kernels state every flag numba would otherwise inherit
(:mod:`suture_bt.perception.compiled`): a kernel is the same code whichever caller compiles it
first, so the on-disk cache cannot carry one process's history into another's answers."""

import importlib
import inspect
import os
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
from numba import njit, prange
from numba.core.registry import CPUDispatcher

import suture_bt.perception as perception
from suture_bt.perception.compiled import ERROR_MODEL, kernel
from suture_bt.perception.kernel_cache import PackageStampedCache


def _weight(r, s):
    q = 1.0 + (r / s) ** 2
    return 1.0 / q


def _callers(callee):
    """A parallel caller with fastmath licences and a plain serial one, both calling callee."""

    @njit(parallel=True, fastmath={"contract"})
    def parallel_caller(r, s, out):
        for i in prange(r.shape[0]):
            out[i] = callee(r[i], s)

    @njit
    def serial_caller(r, s, out):
        for i in range(r.shape[0]):
            out[i] = callee(r[i], s)

    return parallel_caller, serial_caller


def _float_ops(dispatcher) -> list[str]:
    """The callee's floating-point instructions with their licences (``fmul contract``...)."""
    ir = dispatcher.inspect_llvm(dispatcher.signatures[0])
    return sorted(set(re.findall(r"= (f(?:div|mul|add)[a-z ]*) double", ir)))


def _compiled_first_by_each_caller(decorate) -> tuple[list[str], list[str]]:
    """One function decorated twice: the first copy compiled by the parallel caller, the
    second by the serial one."""
    first, second = decorate(_weight), decorate(_weight)
    r, out = np.linspace(0.0, 1.0, 8), np.empty(8)
    _callers(first)[0](r, 1.0, out)
    _callers(second)[1](r, 1.0, out)
    return _float_ops(first), _float_ops(second)


def test_a_kernel_is_the_same_code_whichever_caller_compiles_it_first():
    by_parallel, by_serial = _compiled_first_by_each_caller(kernel(cache=False))
    assert by_parallel == by_serial
    assert "fdiv" in by_parallel  # no licence inherited


def test_plain_njit_takes_the_first_callers_licences():
    """The trap :func:`kernel` avoids (numba 0.68): the caller's fastmath reaches the callee."""
    by_parallel, by_serial = _compiled_first_by_each_caller(njit)
    assert by_parallel != by_serial
    assert "fdiv contract" in by_parallel and "fdiv" in by_serial


def _perception_dispatchers() -> dict[str, CPUDispatcher]:
    found = {}
    for info in pkgutil.iter_modules(perception.__path__):
        module = importlib.import_module(f"{perception.__name__}.{info.name}")
        for name, obj in vars(module).items():
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == module.__name__:
                found[f"{info.name}.{name}"] = obj
    return found


def test_every_compiled_kernel_of_the_localiser_states_its_flags_and_is_cached():
    dispatchers = _perception_dispatchers()
    assert len(dispatchers) >= 25, sorted(dispatchers)  # lm_step, edge_kernel, tissue_cut...
    for name, d in dispatchers.items():
        options = d.targetoptions
        assert options.get("error_model") == ERROR_MODEL, name
        assert "fastmath" in options, name
        assert isinstance(d._cache, PackageStampedCache), name  # cached on disk, stamped


_CHILD = """
import hashlib
import sys
import numpy as np
sys.path.insert(0, {tests!r})
{first}
from perception_helpers import MODEL, poses_near_the_needle
from suture_bt.perception.edge_kernel import edge_normal_equations
from suture_bt.perception.fit_solver import FD_STEPS
rays, T, T6 = poses_near_the_needle()
out = edge_normal_equations(T, T6, FD_STEPS, rays, MODEL, 1.0, "cauchy")
print(hashlib.sha1(b"".join(np.ascontiguousarray(a).tobytes() for a in out)).hexdigest())
"""

#: A kernel without fastmath that squares a number, compiled first: before
#: :mod:`~suture_bt.perception.compiled`, it left numba's shared power routine without
#: licences for the edge kernel's robust weight, which took it.
_SQUARE_FIRST = """
from suture_bt.perception.rival_probe import _pose_offset
_pose_offset(np.eye(4), np.eye(4) + 0.01)
"""


def _edge_system_bits(cache_dir: Path, first: str) -> str:
    """The edge system's output (hashed) in a fresh process compiling into an empty cache
    after running ``first``."""
    code = _CHILD.format(tests=str(Path(__file__).parent), first=first)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    return out.stdout.strip().splitlines()[-1]


def test_the_edge_system_has_the_same_bits_whatever_the_process_compiled_before(tmp_path):
    """numba compiles its own routines (``x ** n``, array reductions...) once per process
    with the licences of the first kernel that uses them, then links them into every later
    one: a kernel's bits depended on what the process compiled before it (the tests' order
    against a run's)."""
    assert _edge_system_bits(tmp_path / "a", _SQUARE_FIRST) == _edge_system_bits(tmp_path / "b", "")


def test_no_compiled_kernel_raises_to_a_power():
    """``x ** 2`` in a kernel compiles numba's shared power routine (see the test above):
    kernels write the product."""
    for name, d in _perception_dispatchers().items():
        source = inspect.getsource(d.py_func)
        code = "\n".join(line.split("#")[0] for line in source.splitlines())
        body = code.split('"""')[-1] if code.count('"""') >= 2 else code
        assert "**" not in body, name
