"""Keep pybullet's C-level banners off the user's terminal: the build-time banner it writes to
stderr (fd 2) on first import, and the EGL plugin's on stdout (fd 1) when it first renders
and when it disconnects."""

from __future__ import annotations

import contextlib
import os
import sys


@contextlib.contextmanager
def quiet_fd(fd: int):
    """Silence C-level output on a file descriptor (pybullet plugin banners)."""
    try:
        (sys.stdout if fd == 1 else sys.stderr).flush()
        saved = os.dup(fd)
    except (OSError, ValueError):
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)
        os.close(devnull)


def import_pybullet_quietly() -> None:
    """Import pybullet with its banner suppressed; a no-op once it is imported."""
    if "pybullet" in sys.modules:
        return
    with quiet_fd(2):
        import pybullet  # noqa: F401
