"""One thread count for both compute pools of a process: torch's and numba's.

Both use OpenMP, and in this environment they share one OpenMP runtime: numba's first
parallel call sets its thread count (every core) for the whole process, so a
``torch.set_num_threads(n)`` made before it is silently undone. The network's outputs
depend on torch's thread count (how a convolution's sums are split: about 1e-6 in its
probabilities), so a count that changes with the machine's cores changes a run's bits.
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
