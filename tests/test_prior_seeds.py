"""Starts from a held needle's priors: circles through the pinch point, across the jaws,
nearest a port, placed where the needle is held."""

import numpy as np
from perception_helpers import MODEL, arc_point

from suture_bt.perception.needle_prior import AcrossJawsPrior, HeldPrior, PortPrior
from suture_bt.perception.prior_seeds import SEED_PLACES, SEED_TURNS, seed_poses


def test_seed_poses_pass_the_pinch_point_with_the_held_face_and_through_the_port():
    pinch = np.array([0.01, 0.02, 0.1])
    face = np.array([0.3, 0.2, -0.9])
    held = HeldPrior("psm1", pinch, 0.001)
    jaws = AcrossJawsPrior("psm1", face, 30.0)
    seeds = seed_poses([held, jaws], MODEL)
    assert len(seeds) == SEED_TURNS * SEED_PLACES
    assert max(held.miss(T, MODEL) for T in seeds) < 1e-9
    assert max(jaws.angle_deg(T) for T in seeds) < 1e-6
    assert len(seed_poses([held], MODEL)) == 0  # the face is needed to pin the plane
    port_at = arc_point(seeds[7], MODEL.tip_angle + 0.3)
    port = PortPrior("entry1", port_at, 0.003)
    near = seed_poses([held, jaws, port], MODEL)
    assert len(near) == 2 * SEED_PLACES  # the two circles through pinch and port
    circle = [abs(np.linalg.norm(port_at - T[:3, 3]) - MODEL.radius) for T in near]
    assert max(circle) < 1e-9  # every seed's circle passes through the port
    assert min(port.miss(T, MODEL) for T in near) < 1e-6
    beyond = PortPrior("entry1", held.pinch_point + 3 * MODEL.radius * np.array([1, 0, 0]), 0.003)
    assert len(seed_poses([held, jaws, beyond], MODEL)) == 4 * SEED_PLACES  # the nearest turns


def test_seeds_hold_the_needle_where_the_grasp_holds_it_when_the_prior_says():
    pinch = np.array([0.01, 0.02, 0.1])
    jaws = AcrossJawsPrior("psm1", np.array([0.3, 0.2, -0.9]), 30.0)
    a = MODEL.tip_angle + 0.3
    held = HeldPrior("psm1", pinch, 0.001, arc_angle=a, arc_tolerance=0.0005)
    seeds = seed_poses([held, jaws], MODEL)
    assert len(seeds) == SEED_TURNS * 2  # the place and its swap's
    assert max(held.miss(T, MODEL) for T in seeds) < 1e-6
