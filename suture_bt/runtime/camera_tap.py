"""The context's camera, remembering the last frame captured through it (for the recording).

Skills capture through ``context.camera`` (the calibration image, for one); the tap passes
each call through unchanged and keeps only the last frame and a count, so the recording can
log an image that was captured anyway and never renders one itself.
"""

from __future__ import annotations

from typing import Any


class CameraTap:
    """``capture()`` and ``model`` of the wrapped camera view; ``last`` and ``captures``."""

    __slots__ = ("_camera", "last", "captures")

    def __init__(self, camera: Any):
        self._camera = camera
        self.last: Any = None
        self.captures = 0

    @property
    def model(self) -> Any:
        return self._camera.model

    def capture(self) -> Any:
        """The wrapped camera's frame (kept as ``last``)."""
        frame = self._camera.capture()
        self.last, self.captures = frame, self.captures + 1
        return frame

    def __repr__(self) -> str:
        return f"CameraTap({self._camera!r})"
