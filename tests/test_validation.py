"""Interface value checks give a reason naming what was wrong."""

import numpy as np
import pytest

from suture_bt.validation import as_joint_vector, as_pose


def test_joint_vector_accepts_six_values_and_rejects_others():
    np.testing.assert_array_equal(as_joint_vector([0, 1, 2, 3, 4, 5], "q"), np.arange(6.0))
    with pytest.raises(ValueError, match="goal: expected 6 finite"):
        as_joint_vector([0, 1, 2], "goal")
    with pytest.raises(ValueError, match="finite"):
        as_joint_vector([0, 1, np.nan, 3, 4, 5], "q")


def test_pose_must_be_finite_rigid_4x4():
    np.testing.assert_array_equal(as_pose(np.eye(4), "T"), np.eye(4))
    with pytest.raises(ValueError, match="4×4"):
        as_pose(np.eye(3), "T")
    skewed = np.eye(4)
    skewed[0, 1] = 0.5
    with pytest.raises(ValueError, match="orthonormal"):
        as_pose(skewed, "T")
