"""Known phantom geometry: port frames follow the phantom pose; tool poses point into tissue."""

import numpy as np

from suture_bt.geometry import PhantomModel
from suture_bt.transforms import make_transform, rpy_to_matrix


def test_ports_move_with_the_phantom():
    T = make_transform(rpy_to_matrix((0, 0, np.deg2rad(15))), (0.03, -0.02, 0.0))
    moved = PhantomModel(T_world_phantom=T)
    for a, b in zip(PhantomModel().ports(), moved.ports(), strict=True):
        np.testing.assert_allclose(T @ a.T, b.T, atol=1e-12)
    assert moved.num_pairs == 4


def test_entries_face_minus_x_and_exits_plus_x():
    entry, exit_ = PhantomModel().pair(1)
    assert entry.normal[0] < -0.7 and exit_.normal[0] > 0.7
    np.testing.assert_allclose(entry.position, [-0.00374, 0.04419, 0.075])


def test_tip_pose_into_tissue_is_a_rotation_pointing_inward():
    for port in PhantomModel().ports():
        T = port.tip_pose_into_tissue()
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(T[:3, :3]), 1.0, atol=1e-12)
        np.testing.assert_allclose(T[:3, 2], -port.normal, atol=1e-12)
        np.testing.assert_allclose(T[:3, 3], port.position)
