"""Forward kinematics against the SRC's own vectors; closed-form IK round trips and failures."""

import json
from pathlib import Path

import numpy as np
import pytest

from suture_bt.kinematics import (
    JOINT_LIMITS,
    UnreachablePoseError,
    forward_kinematics,
    inverse_kinematics,
)
from suture_bt.kinematics.ik import ik_branches

REFERENCE = Path(__file__).resolve().parents[1].parent / "shared/reference/psm_fk_vectors.json"


def random_q(rng, n):
    q = rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1], size=(n, 6))
    q[:, 2] = rng.uniform(0.03, JOINT_LIMITS[2, 1], size=n)
    return q


@pytest.mark.skipif(not REFERENCE.exists(), reason="shared/reference is not beside this checkout")
def test_fk_matches_src_reference_vectors():
    data = json.loads(REFERENCE.read_text())
    assert len(data["vectors"]) >= 25
    for v in data["vectors"]:
        np.testing.assert_allclose(forward_kinematics(v["q"]), v["T_tip_in_base"], atol=1e-9)


def test_fk_at_zero_matches_design_axes():
    T = forward_kinematics([0, 0, 0.1, 0, 0, 0])
    # DESIGN.md §5: tip x along base y, y along base x, z along -base z.
    np.testing.assert_allclose(T[:3, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(T[:3, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1], atol=1e-12)


def test_ik_round_trip_1000_random_configurations(rng):
    for q in random_q(rng, 1000):
        q_ik = inverse_kinematics(forward_kinematics(q), q_current=q)
        np.testing.assert_allclose(q_ik, q, atol=1e-9)


def test_both_wrist_branches_reach_the_pose(rng):
    for q in random_q(rng, 50):
        T = forward_kinematics(q)
        for qb in ik_branches(T):
            np.testing.assert_allclose(forward_kinematics(qb), T, atol=1e-9)


def test_branch_nearest_current_is_chosen(rng):
    q = np.array([0.1, -0.2, 0.12, 0.3, 0.4, -0.2])
    T = forward_kinematics(q)
    other = [b for b in ik_branches(T) if np.abs(b - q).max() > 1e-6][0]
    if np.all(np.abs(other) <= JOINT_LIMITS[:, 1]) and other[2] >= 0:
        np.testing.assert_allclose(inverse_kinematics(T, q_current=other), other, atol=1e-9)
    np.testing.assert_allclose(inverse_kinematics(T, q_current=q), q, atol=1e-9)


def test_unreachable_pose_names_the_joint():
    T = forward_kinematics([0, 0, 0.1, 0, 0, 0])
    T[2, 3] = -0.5  # far beyond the insertion limit
    with pytest.raises(UnreachablePoseError, match="joint 3"):
        inverse_kinematics(T)
