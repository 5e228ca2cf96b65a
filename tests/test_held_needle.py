"""Where a held needle may be: its believed arc, or the two circles through the pinch point."""

from types import SimpleNamespace

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.skills.context import NeedleBelief
from suture_bt.skills.grasps import GRASP_DEPTH, hand
from suture_bt.skills.held_needle import (
    ARC_SAMPLES,
    CIRCLE_SAMPLES,
    clearance_at,
    needle_place_sets,
    needle_places,
)
from suture_bt.transforms import make_transform, rpy_to_matrix

NEEDLE = NeedleModel()
ARM = SimpleNamespace(name="psm2")
#: A jaw 30 mm above the middle of the ports, tilted, its tip z pointing roughly down.
T_TIP = make_transform(rpy_to_matrix((np.pi - 0.3, 0.2, 0.7)), (0.0, 0.01, 0.105))


def make_ctx(belief=None):
    return SimpleNamespace(phantom=PhantomModel(np.eye(4)), needle=NEEDLE, belief=belief)


def believed(holder: str, arc_angle: float = 2.0) -> NeedleBelief:
    T_tip_needle = hand(NEEDLE, arc_angle)
    return NeedleBelief(T_TIP @ T_tip_needle, 0.0, "test", holder=holder, T_tip_needle=T_tip_needle)


def in_tip_frame(points: np.ndarray) -> np.ndarray:
    return (points - T_TIP[:3, 3]) @ T_TIP[:3, :3]


def test_unknown_grasp_gives_the_two_circles_through_the_pinch_point():
    sets = needle_place_sets(make_ctx(), ARM, T_TIP)
    assert len(sets) == 2
    r = NEEDLE.radius
    for points, side in zip(sets, (1.0, -1.0), strict=True):
        local = in_tip_frame(points)
        assert local.shape == (1 + CIRCLE_SAMPLES, 3)
        np.testing.assert_allclose(local[0], [0.0, 0.0, -GRASP_DEPTH], atol=1e-12)
        # all in the tip's x-y plane through the pinch, one radius from that side's centre
        np.testing.assert_allclose(local[:, 2], -GRASP_DEPTH, atol=1e-12)
        centre = np.array([0.0, side * r, -GRASP_DEPTH])
        np.testing.assert_allclose(np.linalg.norm(local - centre, axis=1), r, atol=1e-12)


@pytest.mark.parametrize("arc_angle", [1.3, 2.0, 2.9])
def test_a_believed_grasp_by_this_arm_gives_its_arc(arc_angle):
    belief = believed("psm2", arc_angle)
    (points,) = needle_place_sets(make_ctx(belief), ARM, T_TIP)
    assert points.shape == (ARC_SAMPLES, 3)
    T_needle = T_TIP @ belief.T_tip_needle
    ends = NEEDLE.point_at([NEEDLE.tip_angle, NEEDLE.base_angle]) @ T_needle[:3, :3].T
    np.testing.assert_allclose(points[[0, -1]], ends + T_needle[:3, 3], atol=1e-12)
    # the arc passes through the pinch point at its held angle
    pinch = T_TIP[:3, 3] - GRASP_DEPTH * T_TIP[:3, 2]
    held = NEEDLE.point_at(arc_angle) @ T_needle[:3, :3].T + T_needle[:3, 3]
    np.testing.assert_allclose(held, pinch, atol=1e-12)


def test_a_belief_held_by_the_other_arm_leaves_the_grasp_unknown():
    sets = needle_place_sets(make_ctx(believed("psm1")), ARM, T_TIP)
    assert len(sets) == 2 and all(len(s) == 1 + CIRCLE_SAMPLES for s in sets)
    np.testing.assert_array_equal(needle_places(make_ctx(), ARM, T_TIP), np.vstack(sets))


def test_clearance_is_the_least_height_over_the_places_and_their_displacements():
    ctx = make_ctx()
    places = needle_places(ctx, ARM, T_TIP)
    still = clearance_at(ctx, ARM, T_TIP, np.zeros((1, 3)))
    assert still == pytest.approx(float(np.min(height_above_tissue(ctx.phantom, places))))
    assert still > 0.01  # held well above the tissue
    lowered = clearance_at(ctx, ARM, T_TIP, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -0.004]]))
    assert still - 0.004 - 1e-9 <= lowered < still - 0.001
