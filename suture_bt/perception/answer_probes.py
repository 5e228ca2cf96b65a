"""The polished answer probed for a cheaper pose or a near-equal rival (:mod:`rival_probe`).

The fit's answer is the cheapest polished final, but the search's starts may all have missed
the needle's own basin. Four probes descend from the answer: its depth-mirror twin with the
same end pixels, slides along its own circle (when an end is hidden), small turns, and the
rival probe. The first three replace the answer when they find a cheaper pose (they are never
its rivals); the rival probe's poses are kept as rivals, which the refusal gates weigh.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from suture_bt.perception.needle_prior import choose_answer
from suture_bt.perception.rival_probe import (
    FitRays,
    RivalProbe,
    near_starts,
    probe_together,
    slide_starts,
    twin_starts,
)

if TYPE_CHECKING:
    from suture_bt.perception.pose_fit import PoseFitter

#: Starts carried to the mid stage, and to the full polish, by the slide and near probes.
SMALL_PROBE = {"n_mid": 2, "n_polish": 1}


def answer_probes(fitter: PoseFitter, hidden_end: bool) -> list[RivalProbe]:
    """The probes ``fitter`` turns on, in the order they run: the twin, the slides (only
    with a hidden end), the small turns, then the rival probe (last)."""
    stereo, model = fitter.stereo, fitter.model
    probes = []
    if fitter.probe_twin:
        twin = functools.partial(twin_starts, cam=stereo.left)
        probes.append(RivalProbe(stereo, model, starts=twin, n_mid=1, n_polish=1))
    if fitter.probe_slides and hidden_end:
        probes.append(RivalProbe(stereo, model, starts=slide_starts, **SMALL_PROBE))
    if fitter.probe_near:
        near = RivalProbe(stereo, model, starts=near_starts, apart_from_answer=False, **SMALL_PROBE)
        probes.append(near)
    if fitter.probe_rivals:
        probes.append(RivalProbe(stereo, model))
    return probes


def probed(
    fitter: PoseFitter, xf, cf, chosen, rays: FitRays, polish: list, priors, hidden_end: bool
):
    """The polished finals (parameters ``xf``, costs ``cf``; ``chosen`` = the answer's index,
    prior-consistent rows, prior misses) with the probes' poses added: (x, cost, answer index,
    prior-consistent, prior misses, which rows are rivals of the answer).

    Each probe starts from the answer the probes before it left, so all of them descend
    together from the polished answer and a probe is run again only after an earlier one has
    moved it (the same results with one descent per stage instead of four)."""
    b, ok, misses = chosen
    probes = answer_probes(fitter, hidden_end)
    rivals = probes[-1] if fitter.probe_rivals else None
    loss = fitter.final_loss
    near = np.zeros(len(xf), bool)
    start = xf[b].copy()
    results = probe_together(probes, [start] * len(probes), rays, polish, loss)
    for i, probe in enumerate(probes):
        if not np.array_equal(xf[b], start):  # an earlier probe moved the answer
            start = xf[b].copy()
            rest = probes[i:]
            results[i:] = probe_together(rest, [start] * len(rest), rays, polish, loss)
        xs, cs = results[i]
        cs = np.where(fitter.in_range(xs), cs, np.inf)
        if probe is rivals:
            # Rivals are the probe's poses (and the first answer, if one of them replaces
            # it): the other finals are separate basins, mostly the mirror twin, whose small
            # cost gap decides reliably on a whole outline (its own refusals: the priors, the
            # spread).
            near = np.concatenate([near, np.ones(len(xs), bool)])
            near[b] = True
            xf, cf = np.concatenate([xf, xs]), np.concatenate([cf, cs])
        else:
            keep = cs < cf[b]  # a cheaper pose only
            xf, cf = np.concatenate([xf, xs[keep]]), np.concatenate([cf, cs[keep]])
            near = np.concatenate([near, np.zeros(keep.sum(), bool)])
        b, ok, misses = choose_answer(fitter.world_poses(xf), cf, priors, fitter.model)
    return xf, cf, b, ok, misses, near
