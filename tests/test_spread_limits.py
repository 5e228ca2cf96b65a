"""The spread limits: tighter without priors, looser for a needle pinned to a calibrated jaw,
and without priors tighter still for an arc the known tissue hides in part."""

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel
from suture_bt.perception.needle_prior import HeldPrior, PortPrior
from suture_bt.perception.refusal import NeedleNotFound
from suture_bt.perception.spread_limits import (
    HELD_PIN_TOLERANCE,
    IN_TISSUE_SHARE,
    MAX_ANGLE_STD_DEG,
    MAX_ANGLE_STD_DEG_HELD,
    MAX_ANGLE_STD_DEG_IN_TISSUE,
    MAX_ANGLE_STD_DEG_UNAIDED,
    angle_std_limit,
    check_spread_in_tissue,
)

MODEL = NeedleModel()


def _below(z: float):
    """A tissue filling the half space below height ``z`` (world m)."""
    return lambda pts: np.asarray(pts)[:, 2] < z


def _share_below(T: np.ndarray, z: float) -> float:
    arc = MODEL.centerline(64)
    return float(np.mean((arc @ T[:3, :3].T + T[:3, 3])[:, 2] < z))


def test_the_limit_follows_what_the_caller_knows():
    port = PortPrior("entry1", np.zeros(3), 0.003)
    pinned = HeldPrior("psm2", np.zeros(3), HELD_PIN_TOLERANCE)
    loose = HeldPrior("psm2", np.zeros(3), 2 * HELD_PIN_TOLERANCE)
    held = MAX_ANGLE_STD_DEG_HELD
    assert angle_std_limit((), MAX_ANGLE_STD_DEG, held) == MAX_ANGLE_STD_DEG_UNAIDED
    assert angle_std_limit((port,), MAX_ANGLE_STD_DEG, held) == MAX_ANGLE_STD_DEG
    assert angle_std_limit((loose,), MAX_ANGLE_STD_DEG, held) == MAX_ANGLE_STD_DEG
    assert angle_std_limit((pinned, port), MAX_ANGLE_STD_DEG, held) == held


def test_an_arc_half_in_the_tissue_without_priors_is_held_to_the_tighter_limit():
    T = np.eye(4)  # the needle's y axis up: the arc spans world z from 0 (base) to 10 mm
    T[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    z = 0.005
    share = _share_below(T, z)
    assert IN_TISSUE_SHARE <= share < 1.0
    loose = MAX_ANGLE_STD_DEG_IN_TISSUE + 0.1
    with pytest.raises(NeedleNotFound, match="inside the tissue"):
        check_spread_in_tissue(T, loose, (), _below(z), MODEL)
    check_spread_in_tissue(T, MAX_ANGLE_STD_DEG_IN_TISSUE, (), _below(z), MODEL)
    # Priors check the plane; no tissue model, no rule; an arc barely in the tissue is free.
    port = PortPrior("entry1", np.zeros(3), 0.003)
    check_spread_in_tissue(T, loose, (port,), _below(z), MODEL)
    check_spread_in_tissue(T, loose, (), None, MODEL)
    assert _share_below(T, 0.0005) < IN_TISSUE_SHARE
    check_spread_in_tissue(T, loose, (), _below(0.0005), MODEL)
