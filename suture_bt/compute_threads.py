"""One thread count for both compute pools of a process: torch's and numba's.

Both use GNU OpenMP. Observed here: once torch has run, numba's first parallel loop sets the
thread count torch reads to numba's own (every core), so a ``torch.set_num_threads(n)`` made
before it is silently undone (torch.get_num_threads() 1 → 2 on this 2-core machine). The
network's outputs depend on torch's thread count (how a convolution's sums are split: up to
7e-7 in its probabilities), so a count that follows the machine's cores changes a run's bits.
"""

from __future__ import annotations


def set_compute_threads(n: int) -> None:
    """Run torch's and numba's parallel work on ``n`` threads from now on (numba's at most
    its pool's size); numba's pool is started first, so its start cannot undo torch's."""
    if n < 1:
        raise ValueError(f"compute threads must be at least 1, got {n}")
    import numba
    import torch

    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))  # starts numba's pool
    torch.set_num_threads(n)
