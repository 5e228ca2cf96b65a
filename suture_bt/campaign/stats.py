"""Small statistics for campaign reports: Wilson intervals, mean/p95, reason grouping."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable

import numpy as np

#: Two-sided 95 % normal quantile.
Z95 = 1.959963984540054


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n (0..1; (0, 1) when n = 0): honest
    near 0 % and 100 %, where the normal interval collapses."""
    if n <= 0:
        return 0.0, 1.0
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    lo = 0.0 if k == 0 else max(0.0, centre - half)  # exact ends, not float noise
    hi = 1.0 if k == n else min(1.0, centre + half)
    return lo, hi


def rate(k: int, n: int) -> dict[str, float | int | None]:
    """k, n, the rate and its 95 % Wilson interval (JSON-ready)."""
    lo, hi = wilson(k, n)
    return {
        "k": int(k),
        "n": int(n),
        "rate": None if n == 0 else round(k / n, 4),
        "ci95": [round(lo, 4), round(hi, 4)],
    }


def rate_text(r: dict) -> str:
    """``17/20 (85 %, 95 % CI 64-95 %)``."""
    if not r["n"]:
        return "0/0 (-)"
    lo, hi = r["ci95"]
    return f"{r['k']}/{r['n']} ({100 * r['rate']:.0f} %, CI {100 * lo:.0f}-{100 * hi:.0f} %)"


def spread(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """n, mean, p95 and max of the values that are not None (JSON-ready)."""
    v = np.array([x for x in values if x is not None], dtype=float)
    if len(v) == 0:
        return {"n": 0, "mean": None, "p95": None, "max": None}
    return {
        "n": int(len(v)),
        "mean": round(float(v.mean()), 4),
        "p95": round(float(np.percentile(v, 95)), 4),
        "max": round(float(v.max()), 4),
    }


def reason_key(reason: str | None) -> str:
    """A failure reason with its numbers replaced by ``#`` (so like reasons group), ≤ 140
    characters."""
    if not reason:
        return "(no reason given)"
    text = re.sub(r"[-+]?\d+(\.\d+)?", "#", " ".join(reason.split()))
    return text if len(text) <= 140 else text[:137] + "..."
