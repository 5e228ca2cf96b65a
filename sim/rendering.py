"""Per-client renderer choice: the EGL plugin when it loads, TinyRenderer otherwise.

EGL (software Mesa on a CPU) is 2-4× faster than TinyRenderer and follows the pixel-centre
convention exactly (TinyRenderer draws about half a pixel off; the camera compensates). EGL
renders at most 1024×768 internally (DESIGN.md §5), so callers render larger images in tiles
(see :mod:`suture_bt.sim.camera`). Bodies created in a client before the plugin is loaded are
never drawn by it: call :func:`load_renderer` right after connecting (the needle and phantom
bodies do so themselves).
"""

from __future__ import annotations

import os
import pkgutil

import pybullet as p

from suture_bt.sim.quiet import quiet_fd

#: Largest image the EGL plugin renders without upsampling (DESIGN.md §5).
MAX_TILE_WIDTH = 1024
MAX_TILE_HEIGHT = 768

_egl_broken = False


def load_renderer(client: int) -> str:
    """Load the EGL plugin into ``client`` (a no-op when loaded); return "egl" or "tiny".

    pybullet returns the existing plugin when asked again, so this is cheap and stays right
    when a client id is reused after a disconnect. ``SUTURE_BT_RENDERER=tiny`` skips EGL.
    """
    global _egl_broken
    if not p.isConnected(physicsClientId=client):
        raise ValueError(f"pybullet client {client} is not connected")
    if _egl_broken or os.environ.get("SUTURE_BT_RENDERER", "").lower() == "tiny":
        return "tiny"
    spec = pkgutil.get_loader("eglRenderer")
    if spec is None:
        _egl_broken = True
        return "tiny"
    with quiet_fd(1):
        plugin = p.loadPlugin(spec.get_filename(), "_eglRendererPlugin", physicsClientId=client)
    if plugin < 0:
        _egl_broken = True
        return "tiny"
    return "egl"


def renderer_flag(client: int) -> int:
    """The ``renderer=`` value for ``getCameraImage`` on this client."""
    kind = load_renderer(client)
    return p.ER_BULLET_HARDWARE_OPENGL if kind == "egl" else p.ER_TINY_RENDERER
