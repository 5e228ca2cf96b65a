"""Training datasets stored as numbered ``.npz`` shards: found, loaded as plain arrays, joined.

Shards are data, never code: ``np.load`` keeps its default ``allow_pickle=False``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def load_shards(
    folder: str | os.PathLike, pattern: str, make_command: str
) -> dict[str, np.ndarray]:
    """Every array of the shards matching ``pattern`` in ``folder``, concatenated in name order.

    A folder without shards raises FileNotFoundError naming the command that makes them.
    """
    files = sorted(Path(folder).glob(pattern))
    if not files:
        raise FileNotFoundError(
            f"no {pattern} files in {folder} (create them with `{make_command}`)"
        )
    parts = [dict(np.load(f)) for f in files]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
