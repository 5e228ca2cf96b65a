"""Both eyes' independent image work at once: the right eye's on a worker thread while the
calling thread does the left's. OpenCV and numpy release the GIL on full-resolution images,
so on two cores a stage that works each eye alone takes little more than one eye's time.

Results are the same bits as one eye after the other (each eye's work reads only its own
inputs), and so are the errors: the left eye's is raised before the right's.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")

#: The worker and the process that started it: a forked child (a campaign's trial) has the
#: parent's pool object but not its thread, so it starts its own.
_POOL: tuple[ThreadPoolExecutor, int] | None = None


def _pool() -> ThreadPoolExecutor:
    """The one worker thread the right eye's work runs on (started on first use)."""
    global _POOL
    if _POOL is None or _POOL[1] != os.getpid():
        _POOL = (ThreadPoolExecutor(max_workers=1, thread_name_prefix="right-eye"), os.getpid())
    return _POOL[0]


def both_eyes(work: Callable[[int], T]) -> tuple[T, T]:
    """``(work(0), work(1))``, the two run at once. When both raise, the left eye's (0)
    error is the one raised, as if the eyes had run one after the other; the right eye's
    work is always finished before this returns or raises."""
    right = _pool().submit(work, 1)
    try:
        left = work(0)
    finally:
        right_error = right.exception()  # waits for the right eye either way
    if right_error is not None:
        raise right_error
    return left, right.result()
