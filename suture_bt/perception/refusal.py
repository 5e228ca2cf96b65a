"""The localiser's refusal: the needle is not seen well enough, with the reason why."""

from __future__ import annotations


class NeedleNotFound(Exception):
    """The needle is not visible enough to estimate its pose; ``reason`` says why.
    ``unseen_eye`` names an image in which nothing of a needle was seen ("left", "right");
    ``best`` is the refused best fit (T_cam_needle) when one was made, for a caller whose task
    knowledge can check it (never an answer by itself)."""

    def __init__(self, reason: str, unseen_eye: str | None = None, best=None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.unseen_eye = unseen_eye
        self.best = best
