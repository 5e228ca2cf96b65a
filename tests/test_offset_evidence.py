"""What a look says about an uncalibrated holder's offset: an eye that saw nothing of the
needle rules out the offsets that would show it; needle seen where it is rules out those
under which it could not be in the jaw."""

import numpy as np
import pytest
from skill_helpers import CAMERA, make_arm, make_ctx

from suture_bt.kinematics import forward_kinematics, inverse_kinematics
from suture_bt.planning import to_base
from suture_bt.skills.grasps import GRASP_DEPTH
from suture_bt.skills.offset_evidence import (
    held_circles,
    offset_grid,
    seen_offsets,
    unseen_offsets,
)
from suture_bt.skills.presentation import candidate_poses


def _pinch_px(ctx, arm, q, dq):
    q = np.array(q, float)
    q[:3] += dq
    T = arm.base_frame() @ forward_kinematics(q)
    p = T[:3, 3] - GRASP_DEPTH * T[:3, 2]
    return CAMERA.model.left.project(p[None])[0]


def _centre_look(arm):
    """Joints that put the pinch point at the left image's centre, 62 mm away."""
    centre = CAMERA.model.left.T_world_cam @ np.array([0.0, 0.0, 0.062, 1.0])
    T = np.eye(4)
    T[:3, :3] = CAMERA.model.left.T_world_cam[:3, :3]
    T[:3, 3] = centre[:3] + GRASP_DEPTH * T[:3, 2]
    return inverse_kinematics(to_base(T, arm.base_frame()), arm.servo.setpoint_jp())


def _seen_needle(arm, q, dq, r=0.01018):
    """Pixels (left, right) of a needle arc held across the jaws with the true offset ``dq``."""
    q = np.array(q, float)
    q[:3] += dq
    arc = held_circles(arm.base_frame() @ forward_kinematics(q), r, samples=48)[:20]
    return tuple(cam.project(arc) for cam in (CAMERA.model.left, CAMERA.model.right))


def test_a_seen_needle_keeps_the_true_offset_and_rules_out_those_it_cannot_be_held_at():
    ctx, arm = make_ctx(), make_arm("psm2")
    q = _centre_look(arm)
    true = np.array([np.deg2rad(-4.0), np.deg2rad(-3.5), -0.001])
    grid = np.vstack([offset_grid(), true[None]])
    left = seen_offsets(ctx, arm, q, _seen_needle(arm, q, true), grid)
    assert np.any(np.all(np.isclose(left, true), axis=1))
    assert len(left) < 0.5 * len(grid)


def test_a_look_that_saw_no_needle_pixels_rules_out_nothing_by_seen_evidence():
    ctx, arm = make_ctx(), make_arm("psm2")
    grid = offset_grid()
    empty = (np.zeros((0, 2)), np.zeros((0, 2)))
    assert len(seen_offsets(ctx, arm, _centre_look(arm), empty, grid)) == len(grid)


def test_an_unseen_needle_at_the_image_centre_rules_out_the_offsets_that_keep_it_there():
    ctx, arm = make_ctx(), make_arm("psm2")
    centre = CAMERA.model.left.T_world_cam @ np.array([0.0, 0.0, 0.062, 1.0])
    T = np.eye(4)
    T[:3, :3] = CAMERA.model.left.T_world_cam[:3, :3]
    T[:3, 3] = centre[:3] + GRASP_DEPTH * T[:3, 2]
    q = inverse_kinematics(to_base(T, arm.base_frame()), arm.servo.setpoint_jp())
    grid = offset_grid()
    left = unseen_offsets(ctx, arm, q, "left", grid)
    assert 0 < len(left) < len(grid)
    assert not np.any(np.all(np.abs(left) < 1e-12, axis=1))  # the zero offset is out
    cam = CAMERA.model.left
    for dq in left:  # every offset kept puts the pinch near the border or outside
        u, v = _pinch_px(ctx, arm, q, dq)
        assert min(u, v, cam.width - u, cam.height - v) < 350


def test_offsets_left_by_a_refusal_move_the_presentation():
    ctx, arm = make_ctx(), make_arm("psm2")
    first = candidate_poses(ctx, arm, limit=1)[0]
    grid = offset_grid()
    up = grid[grid[:, 1] <= -0.5 * grid[:, 1].max()]  # only offsets of one sign on joint 2
    arm.possible_offsets = up
    moved = candidate_poses(ctx, arm, limit=1)[0]
    assert np.linalg.norm(moved[:3, 3] - first[:3, 3]) > 1e-3


@pytest.mark.parametrize("eye", ["left", "right"])
def test_a_needle_far_out_of_view_rules_out_nothing(eye):
    ctx, arm = make_ctx(), make_arm("psm2")
    q = arm.servo.setpoint_jp()  # the Task 3 start: the needle held close, out of the view
    grid = offset_grid()
    left = unseen_offsets(ctx, arm, q, eye, grid)
    assert len(left) >= 0.5 * len(grid)
