"""The localiser's refusal: the needle is not seen well enough, with the reason why."""

from __future__ import annotations


class NeedleNotFound(Exception):
    """The needle is not visible enough to estimate its pose; ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason
