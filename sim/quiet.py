"""Import pybullet without the build-time banner it writes to stderr (fd 2) on first import."""

from __future__ import annotations

import os
import sys


def import_pybullet_quietly() -> None:
    """Import pybullet with its banner suppressed; a no-op once it is imported."""
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
