"""Training datasets stored as numbered ``.npz`` shards: found, loaded as plain arrays, joined.

Shards are data, never code: ``np.load`` keeps its default ``allow_pickle=False``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def load_shards(
    folder: str | os.PathLike | Sequence[str | os.PathLike], pattern: str, make_command: str
) -> dict[str, np.ndarray]:
    """Every array of the shards matching ``pattern`` in ``folder`` (or in each of several
    folders, in the order given), concatenated in name order.

    A folder without shards raises FileNotFoundError naming the command that makes them.
    """
    folders = [folder] if isinstance(folder, (str, os.PathLike)) else list(folder)
    files = []
    for f in folders:
        found = sorted(Path(f).glob(pattern))
        if not found:
            raise FileNotFoundError(
                f"no {pattern} files in {f} (create them with `{make_command}`)"
            )
        files += found
    parts = [dict(np.load(f)) for f in files]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
