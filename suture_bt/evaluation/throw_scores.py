"""SRC throw scoring from the simulation's ground-truth records, after the run (DESIGN.md §5).

Pure functions on plain records (no pybullet, no ``suture_bt.sim`` import): the phantom's port
crossings (duck-typed ``Crossing``: port, pair, kind, t, inward, lateral, point, tip_out,
src_direction), its tissue entries (``TissueEntry``: t, point, nearest_port, distance,
depth_max), its ``max_strain`` (port name → record with ``.circle``) and, per throw, the
simulated-time window in which it ran. :func:`~suture_bt.evaluation.records.records_from_world`
collects them from a world's ground truth.

A throw i passes when, inside its window, the tip crosses Entry_i inward and then Exit_i
outward, with a lateral distance ≤ 2.5 mm at each crossing, gets ≥ 5 mm out past the exit, and
goes into the tissue nowhere but at Entry_i (a tissue entry more than 2.5 mm from Entry_i is a
stab, unless the tip never got ``CONTACT_DEPTH`` in: a needle lying on the tissue, laid down or
dropped, is pressed into it by about 0.1 mm by the physics contact; that is not a stab). A
tissue entry outside every throw's window (while preparing, or between throws) is charged to
the throw that follows it, or to the last throw: nothing the needle does in the tissue goes
unscored. Tissue strain over 0.5 mm is reported, not failed.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

#: The ±2.5 mm rule: lateral distance at a crossing, and how close a tissue entry must be to
#: the throw's entry port to count as "at the port" (m).
PORT_RADIUS = 2.5e-3
#: A tissue entry whose tip stayed within this distance of where it went in is contact (a
#: needle resting on the tissue, 0.1 mm in on a dev run), not a stab (m; the wire is 0.72 mm
#: thick, a stab goes millimetres deep).
CONTACT_DEPTH = 0.5e-3
#: The tip must get at least this far out past the exit (m).
TIP_OUT_MIN = 5e-3
#: Tissue strain above this is reported (``strain_high``), not failed (m).
STRAIN_REPORT = 0.5e-3

Window = tuple[float, float] | None


@dataclass
class ThrowScore:
    """One throw's SRC score (millimetres and seconds; None: not measured)."""

    pair: int
    passed: bool
    entry_lateral_mm: float | None
    exit_lateral_mm: float | None
    tip_out_mm: float | None
    strain_mm: float | None
    stab_mm: float | None
    sim_time_s: float | None
    failure: str | None

    @property
    def strain_high(self) -> bool:
        """True when the tissue strain exceeded 0.5 mm (reported, not a failure)."""
        return self.strain_mm is not None and self.strain_mm > STRAIN_REPORT * 1e3

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready values: floats rounded to 4 decimals, None kept, plus ``strain_high``."""
        out = asdict(self)
        for k, v in out.items():
            if isinstance(v, float):
                out[k] = round(float(v), 4)
        out["strain_high"] = self.strain_high
        return out


def _mm(x: float | None) -> float | None:
    """Metres to millimetres, None kept."""
    return None if x is None else float(x) * 1e3


def _in_window(t: float, window: tuple[float, float]) -> bool:
    """Whether a time lies in a closed window."""
    return window[0] <= t <= window[1]


def _pick_crossings(crossings: Sequence[Any], pair: int, window: tuple[float, float]):
    """(entry, exit, exit_before_entry): the first SRC exit of Exit_i that follows an SRC entry
    of Entry_i in the window, and the last such entry before it (a retry's entry counts)."""
    xs = sorted((c for c in crossings if c.pair == pair and _in_window(c.t, window)), key=_t)
    entries = [c for c in xs if c.kind == "entry" and c.src_direction]
    exits = [c for c in xs if c.kind == "exit" and c.src_direction]
    for x in exits:
        before = [e for e in entries if e.t < x.t]
        if before:
            return before[-1], x, False
    entry = entries[-1] if entries else None
    return entry, None, bool(exits and entries and exits[0].t < entries[0].t)


def _t(record: Any) -> float:
    """Sort key: a record's time."""
    return float(record.t)


def _stab(
    entries: Iterable[Any],
    pair: int,
    window: tuple[float, float],
    port_positions: Mapping[str, np.ndarray] | None,
) -> tuple[float, str, float] | None:
    """(distance m, port) of the tissue entry in the window farthest from Entry_i, among those
    not at Entry_i; the distance is from Entry_i when its position is known, else from the
    entry's nearest port (then named), and its time. None when every entry was at the port."""
    own = f"entry{pair}"
    own_pos = None if port_positions is None else port_positions.get(own)
    worst: tuple[float, str, float] | None = None
    for e in entries:
        if not _in_window(e.t, window) or float(getattr(e, "depth_max", 1.0)) < CONTACT_DEPTH:
            continue
        if own_pos is not None:
            d, ref = float(np.linalg.norm(np.asarray(e.point) - np.asarray(own_pos))), own
        elif e.nearest_port == own:
            d, ref = float(e.distance), own
        else:
            d, ref = float(e.distance), f"{e.nearest_port} (nearest port)"
        at_port = d <= PORT_RADIUS and (own_pos is not None or e.nearest_port == own)
        if not at_port and (worst is None or d > worst[0]):
            worst = (d, ref, float(e.t))
    return worst


def score_throw(
    pair: int,
    crossings: Sequence[Any],
    tissue_entries: Sequence[Any],
    max_strain: Mapping[str, Any],
    window: Window,
    port_positions: Mapping[str, np.ndarray] | None = None,
    stab_window: Window = None,
) -> ThrowScore:
    """Score one throw from the run's records (see the module docstring for the rules);
    ``stab_window`` (default: the throw's window) is where its tissue entries are looked for."""
    if window is None:
        return ThrowScore(pair, False, None, None, None, None, None, None, "not attempted")
    window = (float(window[0]), float(window[1]))
    entry, exit_, exit_first = _pick_crossings(crossings, pair, window)
    strains = [max_strain[p].circle for p in (f"entry{pair}", f"exit{pair}") if p in max_strain]
    stab_window = window if stab_window is None else stab_window
    stab = _stab(tissue_entries, pair, stab_window, port_positions)
    reasons = []
    if entry is None:
        reasons.append(f"no entry crossing of entry{pair}")
    elif exit_ is None:
        reasons.append(
            f"exit{pair} crossed before entry{pair}"
            if exit_first
            else f"no exit crossing of exit{pair} after entry{pair}"
        )
    if entry is not None and entry.lateral > PORT_RADIUS:
        reasons.append(f"entry lateral {entry.lateral * 1e3:.1f} mm > {PORT_RADIUS * 1e3} mm")
    if exit_ is not None and exit_.lateral > PORT_RADIUS:
        reasons.append(f"exit lateral {exit_.lateral * 1e3:.1f} mm > {PORT_RADIUS * 1e3} mm")
    if exit_ is not None and exit_.tip_out < TIP_OUT_MIN:
        reasons.append(f"tip out {exit_.tip_out * 1e3:.1f} mm < {TIP_OUT_MIN * 1e3:g} mm")
    if stab is not None:
        side = "before" if stab[2] < window[0] else "after"
        when = "" if _in_window(stab[2], window) else f" at t = {stab[2]:.1f} s, {side} the throw"
        reasons.append(f"stab {stab[0] * 1e3:.1f} mm from {stab[1]}{when}")
    return ThrowScore(
        pair=pair,
        passed=not reasons,
        entry_lateral_mm=_mm(None if entry is None else entry.lateral),
        exit_lateral_mm=_mm(None if exit_ is None else exit_.lateral),
        tip_out_mm=_mm(None if exit_ is None else exit_.tip_out),
        strain_mm=_mm(max(strains)) if strains else None,
        stab_mm=_mm(None if stab is None else stab[0]),
        sim_time_s=window[1] - window[0],
        failure="; ".join(reasons) if reasons else None,
    )


def score_throws(
    crossings: Sequence[Any],
    tissue_entries: Sequence[Any],
    max_strain: Mapping[str, Any],
    windows: Mapping[int, Window],
    pairs: Sequence[int] = (1, 2, 3, 4),
    port_positions: Mapping[str, np.ndarray] | None = None,
) -> list[ThrowScore]:
    """Score every throw in ``pairs`` (a pair missing from ``windows`` was not attempted).

    ``port_positions`` (port name → world position), when given, measures stabs from each
    throw's own entry port; without it, from the entry's nearest port.
    """
    stab_windows = _stab_windows({i: windows.get(i) for i in pairs})
    return [
        score_throw(
            i,
            crossings,
            tissue_entries,
            max_strain,
            windows.get(i),
            port_positions,
            stab_windows.get(i),
        )
        for i in pairs
    ]


def _stab_windows(windows: Mapping[int, Window]) -> dict[int, tuple[float, float]]:
    """Each attempted throw answers for the tissue entries from the end of the throw before it
    (or the run's start) to its own end; the last one also for everything after it."""
    attempted = sorted(((float(w[0]), float(w[1]), i) for i, w in windows.items() if w is not None))
    out, previous_end = {}, -np.inf
    for k, (_, end, i) in enumerate(attempted):
        out[i] = (previous_end, np.inf if k == len(attempted) - 1 else end)
        previous_end = end
    return out


def run_passed(scores: Sequence[ThrowScore]) -> bool:
    """True when there is at least one throw and every throw passed (Task 3 also needs
    :func:`task3_order_ok`)."""
    return bool(scores) and all(s.passed for s in scores)


def src_sequence(crossings: Sequence[Any]) -> list[str]:
    """Ports of the SRC-direction crossings in time order, consecutive repeats collapsed (a
    retry at the same port is one crossing)."""
    out: list[str] = []
    for c in sorted((c for c in crossings if c.src_direction), key=_t):
        if not out or out[-1] != c.port:
            out.append(c.port)
    return out


def task3_order_ok(crossings: Sequence[Any], pairs: Sequence[int] = (1, 2, 3, 4)) -> bool:
    """True when the SRC-direction crossings occur in order Entry1, Exit1, …, Entry4, Exit4
    (:func:`src_sequence`: nothing else, nothing missing)."""
    expected = [f"{kind}{i}" for i in pairs for kind in ("entry", "exit")]
    return src_sequence(crossings) == expected
