"""A held needle's pose fixes an uncalibrated arm's jaw: the offset from the grasp."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from skill_helpers import TRUE_OFFSET, make_arm, make_ctx, presented

from suture_bt.skills.grasp_offset import MAX_ANGLE_DEG, offset_from_grasp
from suture_bt.transforms import make_transform


def test_the_offset_that_puts_the_jaw_on_the_needle_is_found():
    ctx, arm = make_ctx(), make_arm("psm2")
    q, T_needle = presented(arm, ctx)  # held at 150° by an arm offset by TRUE_OFFSET
    found = offset_from_grasp(arm.base_frame(), q, T_needle, ctx.needle)
    assert found is not None
    np.testing.assert_allclose(found.offset, TRUE_OFFSET, atol=1e-6)
    assert found.arc_angle == pytest.approx(np.deg2rad(150.0), abs=1e-5)
    assert "grasp at 150°" in found.summary()


def test_an_estimate_with_the_errors_of_a_look_gives_the_offset_within_a_fraction():
    ctx, arm = make_ctx(), make_arm("psm2")
    q, T_needle = presented(arm, ctx)
    rng = np.random.default_rng(7)
    for _ in range(3):  # 0.2 mm and about 1° off, as a presented look answers
        noisy = T_needle.copy()
        noisy[:3, 3] += rng.normal(0.0, 0.0002, 3)
        turn = Rotation.from_rotvec(np.deg2rad(1.0) * rng.normal(size=3) / np.sqrt(3))
        noisy[:3, :3] = turn.as_matrix() @ noisy[:3, :3]
        found = offset_from_grasp(arm.base_frame(), q, noisy, ctx.needle)
        assert found is not None
        err = np.abs(found.offset - TRUE_OFFSET)
        assert err[0] < np.deg2rad(0.5) and err[1] < np.deg2rad(0.5) and err[2] < 0.0005


def test_a_needle_not_held_as_the_task_holds_it_gives_no_offset():
    ctx, arm = make_ctx(), make_arm("psm2")
    q, T_needle = presented(arm, ctx)
    # Turned 40° about the jaw's closing direction at the held point (far beyond a slip).
    pivot = make_transform(np.eye(3), ctx.needle.point_at(np.deg2rad(150.0)))
    tilt = make_transform(Rotation.from_rotvec([np.deg2rad(40.0), 0, 0]).as_matrix(), np.zeros(3))
    tilted = T_needle @ pivot @ tilt @ np.linalg.inv(pivot)
    assert offset_from_grasp(arm.base_frame(), q, tilted, ctx.needle) is None
    # A needle 30 mm away from the jaw: no offset in the bound reaches it.
    far = T_needle.copy()
    far[:3, 3] += [0.03, 0.0, 0.0]
    assert offset_from_grasp(arm.base_frame(), q, far, ctx.needle) is None
    assert MAX_ANGLE_DEG < 40.0
