"""The needle model reproduces the SRC geometry and scoring points (DESIGN.md §5)."""

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel
from suture_bt.geometry.needle import SCORED_POINTS
from suture_bt.transforms import make_transform, rpy_to_matrix


def test_arc_matches_src_numbers():
    m = NeedleModel()
    assert 120 < np.degrees(m.arc_angle) < 126
    assert 0.021 < m.length < 0.023
    np.testing.assert_allclose(m.base, [-m.radius, 0, 0], atol=1e-12)
    np.testing.assert_allclose(m.tip, SCORED_POINTS["tip"], atol=2e-5)


def test_centerline_runs_base_to_tip_on_the_circle():
    m = NeedleModel()
    pts = m.centerline(20)
    np.testing.assert_allclose(np.linalg.norm(pts, axis=1), m.radius, atol=1e-12)
    np.testing.assert_allclose(pts[0], m.base, atol=1e-12)
    np.testing.assert_allclose(pts[-1], m.tip, atol=1e-12)


def test_tangent_points_in_the_direction_of_travel():
    m = NeedleModel()
    a = np.deg2rad(90.0)
    step = m.point_at(a - 1e-6) - m.point_at(a)
    np.testing.assert_allclose(m.tangent_at(a), step / np.linalg.norm(step), atol=1e-6)


def test_scored_points_follow_the_pose():
    T = make_transform(rpy_to_matrix((0.1, -0.2, 0.3)), (0.01, 0.02, 0.07))
    pts = NeedleModel().scored_points(T)
    np.testing.assert_allclose(pts["base"], T[:3, :3] @ [-0.0102, 0, 0] + T[:3, 3])


def test_chord_is_the_distance_between_base_and_tip():
    m = NeedleModel()
    assert m.chord == pytest.approx(float(np.linalg.norm(m.base - m.tip)), abs=1e-12)
    assert 0.017 < m.chord < 0.019  # about 18 mm for the SRC needle
