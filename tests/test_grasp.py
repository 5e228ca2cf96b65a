"""Grasp geometry: a wire between the jaws is grasped where it lies; one 3 mm away is not."""

import numpy as np
import pytest

from suture_bt.geometry.needle import NeedleModel
from suture_bt.sim.grasp import GRASP_TOLERANCE, check_grasp
from suture_bt.transforms import make_transform, rpy_to_matrix

MODEL = NeedleModel()
A0 = 2.0  # grasp near the middle of the arc


def needle_in_tip(q, along=(1.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0)) -> np.ndarray:
    """T_tip_needle with centre-line point A0 at q and the wire running along ``along``."""
    t = np.array([np.sin(A0), -np.cos(A0), 0.0])
    r = np.array([np.cos(A0), np.sin(A0), 0.0])
    x, z = np.asarray(along, float), np.asarray(normal, float)
    R = np.stack([x, np.cross(z, x), z], 1) @ np.stack([t, r, [0, 0, 1.0]])
    return make_transform(R, np.asarray(q) - R @ MODEL.point_at(A0))


@pytest.fixture
def T_world_tip():
    return make_transform(rpy_to_matrix((0.3, -1.1, 2.0)), (0.01, 0.05, 0.09))


def test_wire_between_jaws_is_grasped_where_it_lies(T_world_tip):
    T_tn = needle_in_tip((0.0, 0.0, -0.002))
    g = check_grasp(T_world_tip, 0.05, T_world_tip @ T_tn, MODEL)
    assert g.ok, g.reason
    np.testing.assert_allclose(g.T_tip_needle, T_tn, atol=1e-9)  # no canonical pose
    assert g.arc_angle == pytest.approx(A0, abs=1e-3)
    assert g.distance < 1e-6


def test_blades_push_wire_onto_pinch_plane(T_world_tip):
    T_tn = needle_in_tip((0.0, 0.001, 0.0))
    g = check_grasp(T_world_tip, 0.0, T_world_tip @ T_tn, MODEL)
    assert g.ok, g.reason
    wire = g.T_tip_needle @ np.r_[MODEL.point_at(A0), 1.0]
    np.testing.assert_allclose(wire[:3], [0, 0, 0], atol=1e-9)
    np.testing.assert_allclose(g.T_tip_needle[:3, :3], T_tn[:3, :3], atol=1e-12)


@pytest.mark.parametrize(
    "offset, along, normal",
    [
        ((0.0, 0.003, 0.0), (1, 0, 0), (0, 0, 1)),  # across the jaw, 3 mm off the pinch plane
        ((0.0, -0.003, 0.0), (1, 0, 0), (0, 1, 0)),  # needle in the pinch plane, shifted
        ((0.003, 0.0, 0.0), (0, 0, 1), (1, 0, 0)),  # along the jaw, 3 mm beside the blades
    ],
)
def test_wire_3mm_away_is_rejected(T_world_tip, offset, along, normal):
    T_tn = needle_in_tip(offset, along, normal)
    g = check_grasp(T_world_tip, 0.0, T_world_tip @ T_tn, MODEL)
    assert not g.ok and g.T_tip_needle is None
    assert "3.00 mm from the jaw's pinch line" in g.reason
    assert g.distance > GRASP_TOLERANCE


def test_other_rejections(T_world_tip):
    ok_pose = T_world_tip @ needle_in_tip((0, 0, 0))
    assert "jaw not closed" in check_grasp(T_world_tip, 0.6, ok_pose, MODEL).reason
    beyond = T_world_tip @ needle_in_tip((0, 0, 0.0025))
    assert "beyond the jaw tip" in check_grasp(T_world_tip, 0.0, beyond, MODEL).reason
    at_blade = T_world_tip @ needle_in_tip((0, 0, 0), along=(0, 1, 0), normal=(1, 0, 0))
    assert "points at a blade" in check_grasp(T_world_tip, 0.0, at_blade, MODEL).reason
    lengthwise = T_world_tip @ needle_in_tip((0, 0, 0), along=(0, 0, 1), normal=(0, 1, 0))
    assert check_grasp(T_world_tip, 0.0, lengthwise, MODEL).ok
    with pytest.raises(ValueError):
        check_grasp(np.eye(3), 0.0, ok_pose, MODEL)
