"""Read where an emerged needle tip stands from one frame, around the pose the arm predicts.

When the localiser refuses a needle that is mostly inside the tissue, the frame still shows its
emerged piece. The hypotheses are poses near the prediction: turned along the needle's own
circle (the in-hand estimate's least certain part is where along the arc the jaw holds it) and,
for a needle that slipped in the jaw on contact with the tissue, also turned about the jaw's
closing axis (normal to the blade faces) through its pinch point by up to ``PIVOT_DEG``: the
way a wire pinched between flat blades turns, which tilts the needle's plane. A hypothesis
*reads* when the frame shows metal along its emerged piece and none along its circle continued
past its tip. Of the readings on the predicted circle the least advanced is taken (it also puts
the jaws nearest the entry); pivoted hypotheses are tried only when none on the circle reads,
and of theirs the best supported is taken (the smallest pivot among equals: over a wide range
of pivots a small one may read a short, partly seen piece).

A needle the tissue holds part way through a pair (dropped there) is read the same way
(:func:`read_hanging`): turned along the circle it was held on, the part of its arc above the
tissue (the phantom's known surface) must show metal and the circle continued past either end,
where above the tissue, must not; the turn whose arc explains most of what the open circle
shows is taken (the middle of the best when several explain it equally: ``on`` is that
share).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from suture_bt.geometry import NeedleModel, PhantomModel, Port
from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.skills import checks
from suture_bt.skills.context import NeedleNotSeen, NeedleSensor
from suture_bt.transforms import make_transform, rpy_to_matrix

#: Turns along the circle tried (deg, + = further in) and pivots about the pinch point (deg,
#: smallest first: up to two slips of the mild profile's 5°, one slip before the insertion's
#: contact and one on it; a campaign trial's needle turned 7.7° and was not read at ±6°).
SCAN_DEG = 30.0
PIVOT_DEG = tuple(sign * 1.5 * k for k in range(1, 8) for sign in (1.0, -1.0))
#: The circle past a reading's tip (deg of arc beyond it) must show no metal.
BEYOND_DEG = (3.0, 15.0)
#: Shares of the emerged piece that must be seen as metal, and of the piece past the tip
#: that may be.
MIN_ON, MAX_OFF = 0.75, 0.25
#: Grid step (deg) of the centre-line samples asked of the frame.
STEP_DEG = 0.5
#: A hanging needle's arc counts as in the open this far above the tissue surface (m); at
#: least ``MIN_OPEN_DEG`` of it must be, for a reading. Turns tried (± deg); the frame shows
#: metal about ``END_SEEN_DEG`` past each end of the arc (measured on three drops part way
#: through pair 1: the hit test's pixel tolerance and the wire's round ends); the share of the
#: open circle whose seen / not seen a reading must explain.
OPEN_ABOVE, MIN_OPEN_DEG = 0.001, 20.0
HANG_SCAN_DEG, END_SEEN_DEG, MIN_AGREE = 45.0, 6.0, 0.9


@dataclass(frozen=True)
class TipReading:
    """A pose the frame supports: ``turn_deg`` along the circle and ``pivot_deg`` about the
    pinch point from the prediction, with the shares seen on and past the emerged piece."""

    T_world_needle: np.ndarray
    turn_deg: float
    pivot_deg: float
    on: float
    off: float

    def describe(self) -> str:
        pivot = f", turned {self.pivot_deg:+.1f}° in the jaw" if self.pivot_deg else ""
        return (
            f"tip read {self.turn_deg:+.0f}° along the arc from the in-hand estimate{pivot}: "
            f"{100 * self.on:.0f} % of its emerged piece seen, {100 * self.off:.0f} % past it"
        )


def tip_out(T_world_needle: np.ndarray, needle: NeedleModel, exit_: Port) -> float:
    """Tip out past the exit (m) of a needle pose; 0 when it does not cross the exit."""
    _, _, numbers = checks.tip_out_past_exit(T_world_needle, needle, exit_)
    return 1e-3 * numbers.get("tip_out_mm", 0.0)


def pivoted(
    T_world_needle: np.ndarray, pinch: np.ndarray, deg: float, axis: np.ndarray
) -> np.ndarray:
    """The needle turned ``deg`` about the world ``axis`` (unit) through the point ``pinch``."""
    R = Rotation.from_rotvec(np.deg2rad(deg) * np.asarray(axis, dtype=float)).as_matrix()
    T = np.array(T_world_needle, dtype=float)
    T[:3, :3] = R @ T[:3, :3]
    T[:3, 3] = pinch + R @ (T[:3, 3] - pinch)
    return T


def read_tip(
    sensor: NeedleSensor,
    needle: NeedleModel,
    predicted: np.ndarray,
    exit_: Port,
    jaw: tuple[np.ndarray, np.ndarray] | None = None,
) -> TipReading | None:
    """The reading of the sensor's last frame (see the module docstring); None when no
    hypothesis reads (no emerged tip in the frame, or no frame). ``jaw``: the holder's pinch
    point and closing axis (world); without it only the predicted circle is tried."""
    try:
        found = _along_circle(sensor, needle, predicted, exit_)
    except NeedleNotSeen:
        return None
    if found is not None:
        T, turn, on, off = found
        return TipReading(T, turn, 0.0, on, off)
    best = None
    for pivot in PIVOT_DEG if jaw is not None else ():
        T_pivot = pivoted(predicted, jaw[0], pivot, jaw[1])
        found = _along_circle(sensor, needle, T_pivot, exit_, best=True)
        if found is not None and (best is None or found[2] - found[3] > best[3] - best[4]):
            T, turn, on, off = found
            best = (T, turn, pivot, on, off)
    return None if best is None else TipReading(*best)


def _along_circle(
    sensor: NeedleSensor, needle: NeedleModel, base: np.ndarray, exit_: Port, best: bool = False
):
    """(pose, turn deg, on, off) of the least advanced turn of ``base`` that reads (``best``:
    the best supported, the least advanced among equals), or None."""
    step = np.deg2rad(STEP_DEG)
    grid = needle.tip_angle + np.arange(
        np.deg2rad(-SCAN_DEG - BEYOND_DEG[1]), np.deg2rad(SCAN_DEG + 90.0), step
    )
    left, right = sensor.hits(base, grid)

    def share(angles: np.ndarray) -> float:
        i = np.clip(np.rint((angles - grid[0]) / step).astype(int), 0, len(grid) - 1)
        return min(float(left[i].mean()), float(right[i].mean()))

    found = None
    for turn in np.deg2rad(np.arange(-SCAN_DEG, SCAN_DEG + 0.01, 1.0)):
        # advanced by ``turn`` along the sweep (which turns the needle about its own −z)
        T = base @ make_transform(rpy_to_matrix((0.0, 0.0, -turn)))
        out = tip_out(T, needle, exit_)
        if out < checks.MIN_TIP_OUT * 0.5:
            continue
        # The piece in front of the exit surface (1 mm kept clear of it), and the circle
        # continued past the tip, in the base needle's angles.
        emerged = needle.tip_angle - turn + np.linspace(0.0, (out - 0.001) / needle.radius, 12)
        beyond = needle.tip_angle - turn - np.deg2rad(np.linspace(*BEYOND_DEG, 8))
        on, off = share(emerged), share(beyond)
        if on >= MIN_ON and off <= MAX_OFF:
            if not best:
                return T, float(np.rad2deg(turn)), on, off
            if found is None or on - off > found[2] - found[3]:
                found = (T, float(np.rad2deg(turn)), on, off)
    return found


def read_hanging(
    sensor: NeedleSensor, needle: NeedleModel, phantom: PhantomModel, predicted: np.ndarray
) -> TipReading | None:
    """The turn along ``predicted``'s circle that the sensor's last frame supports for a
    needle partly in the tissue (see the module docstring), or None when none reads."""
    step = np.deg2rad(STEP_DEG)
    margin = np.deg2rad(HANG_SCAN_DEG + END_SEEN_DEG + BEYOND_DEG[1])
    grid = np.arange(needle.tip_angle - margin, needle.base_angle + margin + step / 2, step)
    try:
        seen = np.minimum(*sensor.hits(predicted, grid))
    except NeedleNotSeen:
        return None
    pts = needle.point_at(grid) @ predicted[:3, :3].T + predicted[:3, 3]
    open_ = height_above_tissue(phantom, pts) > OPEN_ABOVE
    if not open_.any():
        return None
    ends = np.deg2rad(END_SEEN_DEG)
    turns = np.deg2rad(np.arange(-HANG_SCAN_DEG, HANG_SCAN_DEG + 0.01, STEP_DEG))
    scores = np.full(len(turns), -1.0)
    for k, turn in enumerate(turns):
        # advanced by ``turn`` along the sweep: its arc lies at base angles shifted by −turn
        arc = (grid >= needle.tip_angle - turn - ends) & (grid <= needle.base_angle - turn + ends)
        visible = arc & open_
        if visible.sum() * STEP_DEG < MIN_OPEN_DEG or seen[visible].mean() < MIN_ON:
            continue
        scores[k] = float((seen[open_] == arc[open_]).mean())
    if scores.max() < MIN_AGREE:
        return None
    best = turns[scores >= scores.max() - 1e-9]
    turn = float(0.5 * (best.min() + best.max()))
    T = predicted @ make_transform(rpy_to_matrix((0.0, 0.0, -turn)))
    return TipReading(T, float(np.rad2deg(turn)), 0.0, float(scores.max()), 0.0)
