"""A near view that shows only a short piece of the needle answers only a clear winner.

A few millimetres of wire beside a jaw or shaft, or a stub out of a port, are explained by
arcs that go on behind the hider in several directions; what tells them apart is that
piece's faint curvature. The fit's tie ratio (:func:`~.rival_probe.tie_ratio`: the cheapest
clearly different candidate's cost over the answer's) then means less than for a needle
seen whole, as it does far away (:data:`~.rival_probe.MAX_TIE_RATIO_FAR`). Without priors,
an answer nearer than :data:`~.rival_probe.FAR_TIE_DEPTH` that either eye sees over less
than :data:`SHORT_SEEN` of arc (the exposure gate's ``seen``) is refused when such a
candidate costs within :data:`MAX_TIE_RATIO_SHORT` of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from suture_bt.perception.fit_result import PoseFitResult
from suture_bt.perception.needle_prior import NeedlePrior
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.unseen_arc import ArcExposure

if TYPE_CHECKING:  # answer_gates takes its defaults from here
    from suture_bt.perception.answer_gates import AnswerGates

#: Arc (m) seen by an eye under which a near view is short. Over the report files of
#: sessions 20-45 (development data now), the answers whose needle lay nearer than 80 mm,
#: without priors and seen under 6 mm in an eye, were 306 right, the lowest tie 1.255, and 4
#: wrong: 15.9 mm / 105° (28162783 `handover` #4, 5.9 mm seen, tie 1.054), 11.8 mm / 72°
#: (74885920 `handover` #22, 4.2 mm, 1.095: refused here, its answer 55 mm away), 18.6 mm /
#: 142° (82806613 `in_port` #30, 3.8 mm, 1.203: not refused, its answer lies 88 mm away, where
#: seven right short answers held ties of 1.12-1.20) and one at 1.371 (47151840 `in_port` #0,
#: 5.6° off; at session 46's code its answer ties at 1.092 and is refused here).
#: Seen longer, ties up to 1.25 held 765 right answers and one wrong (78041143 `in_port` #29,
#: 6.3 mm, 1.147). Both limits lie where those files put them, with little room either way:
#: set on them, to be judged on seeds drawn after.
SHORT_SEEN = 0.006
#: The tie ratio refused for a short near view without priors (see :data:`SHORT_SEEN`).
MAX_TIE_RATIO_SHORT = 1.25


def check_short_tie(
    fit: PoseFitResult, exposure: ArcExposure, gates: AnswerGates, priors: Sequence[NeedlePrior]
) -> None:
    """Refuse ``fit`` (its arc's ``exposure``) when it is a short near view without priors
    (:meth:`~.answer_gates.AnswerGates.short_tie_limit`) and its tie ratio within the limit."""
    depth = float(fit.T_cam_needle[2, 3])
    limit = gates.short_tie_limit(min(exposure.seen), depth, priors)
    if fit.tie_ratio <= limit:
        raise NeedleNotFound(
            f"only {1e3 * min(exposure.seen):.1f} mm of the arc is seen (left "
            f"{1e3 * exposure.seen[0]:.1f}, right {1e3 * exposure.seen[1]:.1f}; short under "
            f"{1e3 * gates.short_seen:.0f} mm at {1e3 * depth:.0f} mm) and a clearly different "
            f"pose explains it almost as well (cost {fit.tie_ratio:.3f}x the answer's, limit "
            f"{limit:.2f}): the piece does not tell which way the needle goes on"
        )
