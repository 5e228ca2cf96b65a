"""Shared helpers for the weights-file tests: a pickle that would run code, one-line checks."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from suture_bt.weights_file import WeightsError


class Evil:
    """Unpickling this object would create ``marker`` (it stands for arbitrary code)."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def assert_refused(load: Callable, path: Path, reason: str | None, hint: str) -> str:
    """``load(path)`` raises WeightsError matching ``reason``: one line naming path and hint."""
    with pytest.raises(WeightsError, match=reason) as info:
        load(path)
    text = str(info.value)
    assert "\n" not in text and str(path) in text and hint in text
    return text
