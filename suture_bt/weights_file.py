"""Network weights files that are data, never code: tagged, plain, loaded with weights_only=True.

A weights file is ``{"format": tag, "state": state, "meta": meta}`` written by ``torch.save``.
``state`` holds tensors (state dicts, possibly nested in dicts), ``meta`` only plain Python
values (dict/list/str/int/float/bool/None) and tensors: :func:`save_weights_file` converts
numpy arrays and scalars to lists and numbers, because ``torch.load(weights_only=True)`` refuses
anything else. Loading never unpickles code; every failure (missing, corrupted, foreign or
mismatched file) raises :class:`WeightsError` with one line that names the file and what to do.
"""

from __future__ import annotations

import pickle
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

_PLAIN = (str, int, float, bool, type(None), torch.Tensor)


class WeightsError(ValueError):
    """A weights file cannot be used: unreadable, not data-only, of another kind or mismatched."""


class WeightsNotFoundError(WeightsError, FileNotFoundError):
    """The weights file does not exist."""


def plain(value: Any, where: str = "meta") -> Any:
    """``value`` with numpy arrays/scalars as lists/numbers and tuples as lists; else TypeError."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, _PLAIN):
        return value
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise TypeError(f"{where}: key {k!r} is not a string")
            out[k] = plain(v, f"{where}[{k!r}]")
        return out
    if isinstance(value, list | tuple):
        return [plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise TypeError(f"{where}: {type(value).__name__} cannot be stored in a weights file")


def save_weights_file(path: Path | str, fmt: str, state: Mapping, meta: Mapping) -> None:
    """Write tensors ``state`` and plain ``meta`` (numpy converted) under the format tag."""
    blob = {"format": fmt, "state": dict(state), "meta": plain(meta)}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(blob, path)


def _one_line(text: str, limit: int = 160) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def load_weights_file(path: Path | str, fmt: str, hint: str) -> tuple[dict, dict]:
    """(state, meta) of a weights file with tag ``fmt``; ``hint`` says how to make a good one."""
    path = Path(path)
    if not path.exists():
        raise WeightsNotFoundError(f"{path}: weights file not found; {hint}")
    if not path.is_file():
        raise WeightsError(f"{path}: not a file; {hint}")
    try:
        with warnings.catch_warnings():  # torch warns about pickle protocols of foreign files
            warnings.simplefilter("ignore")
            blob = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:
        raise WeightsError(
            f"{path}: refused, not a data-only weights file (it holds objects other than "
            f"tensors and plain data, or is no torch file; weights are data, never code); {hint}"
        ) from None
    except Exception as exc:  # noqa: BLE001 - any unreadable file is reported the same way
        reason = _one_line(f"{type(exc).__name__}: {exc}")
        raise WeightsError(f"{path}: not a readable weights file ({reason}); {hint}") from None
    tag = blob.get("format") if isinstance(blob, dict) else None
    if tag != fmt:
        raise WeightsError(f"{path}: not a {fmt} weights file (format {tag!r}); {hint}")
    state, meta = blob.get("state"), blob.get("meta")
    if not isinstance(state, dict) or not isinstance(meta, dict):
        raise WeightsError(f"{path}: {fmt} file without a state or meta dict; {hint}")
    return state, meta


def load_state(module: nn.Module, state: Any, path: Path | str, hint: str) -> None:
    """``module.load_state_dict(state)``, a mismatch reported as one-line :class:`WeightsError`."""
    try:
        module.load_state_dict(state)
    except (RuntimeError, KeyError, TypeError, AttributeError) as exc:
        reason = _one_line(exc)
        raise WeightsError(
            f"{path}: weights do not match {type(module).__name__} ({reason}); {hint}"
        ) from None
