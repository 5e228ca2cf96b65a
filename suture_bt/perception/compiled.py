"""One decorator for the localiser's compiled (numba) kernels, so that a kernel is the same
code whatever the process compiled before it.

numba compiles a kernel once per argument types and caches it on disk under that key alone.
Two things a kernel's code took from the process's history, not from its source:

- **Flags it leaves unset.** The error model and fastmath are inherited from the caller that
  compiles a function first (a ``prange`` body's callees get the ``"numpy"`` error model, a
  serial caller's the ``"python"`` one; a caller's fastmath licences reach a callee without
  its own). :func:`kernel` states both.
- **numba's own routines.** ``x ** 2`` compiles numba's power routine, as array reductions
  compile theirs, once per process with the licences of the first kernel that needs it
  (numba keys these by code, types and error model, not fastmath) and links that copy into
  every later kernel. The edge kernel's robust weight (``FAST_MATH``) took a power routine
  compiled either with its licences or without them, whichever kernel squared a number first.
  Kernels write products instead (``tests/test_compiled.py`` checks both).

Found in session 49: the README's first command ran 48.9 s simulated from a fresh clone
whose tests had filled the cache and 47.9 s where a run had (DESIGN.md §4: same scene and
seed, same run)."""

from __future__ import annotations

from collections.abc import Callable, Set

from numba import njit

from suture_bt.perception.kernel_cache import cache_by_package

#: numba's error model for every kernel: what its parallel loop bodies use anyway (NaN or inf
#: from a division by zero, no check), so a kernel is the same code wherever it is called.
ERROR_MODEL = "numpy"


def kernel(
    *,
    parallel: bool = False,
    fastmath: bool | Set[str] = False,
    inline: str = "never",
    cache: bool = True,
) -> Callable:
    """``numba.njit`` with the error model and fastmath stated (never inherited) and, by
    default, the on-disk cache on, stamped by every source of the package
    (:mod:`~.kernel_cache`: numba's own stamp misses a change in a callee's file)."""
    fm = set(fastmath) if isinstance(fastmath, Set) else bool(fastmath)
    jit = njit(parallel=parallel, fastmath=fm, error_model=ERROR_MODEL, inline=inline)
    return (lambda fn: cache_by_package(jit(fn))) if cache else jit
