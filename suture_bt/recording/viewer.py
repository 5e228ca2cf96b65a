"""Can a rerun viewer start here? (a display and the ``rerun`` executable), and start one."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path


def rerun_executable() -> str | None:
    """The ``rerun`` viewer executable next to this Python, or on PATH."""
    beside = Path(sys.executable).with_name("rerun")
    if beside.exists():
        return str(beside)
    return shutil.which("rerun")


def why_no_viewer() -> str | None:
    """None when a viewer can start; otherwise the reason, in one line."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        if sys.platform.startswith("linux"):
            return "no display (DISPLAY and WAYLAND_DISPLAY are unset)"
    if rerun_executable() is None:
        return "the rerun viewer executable is not installed (pip install rerun-sdk)"
    return None


def open_in_viewer(path: Path) -> subprocess.Popen:
    """Start the viewer on a saved recording, detached from this process."""
    exe = rerun_executable()
    if exe is None:
        raise RuntimeError("the rerun viewer executable is not installed")
    return subprocess.Popen(
        [exe, str(path)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
