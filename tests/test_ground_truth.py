"""The ground-truth API reports the true state, which the robot interface hides."""

import numpy as np
import pytest

from suture_bt.kinematics import forward_kinematics
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.transforms import invert


@pytest.fixture(scope="module")
def world():
    scene = scene_from_dict(
        {
            "arms": {"psm1": {"joint_offset": "C"}},
            "needle": {"start": "in_psm2_jaw"},
            "camera": {"width": 160, "height": 90},
        }
    )
    with World.from_scene(scene) as w:
        w.step(0.05)
        yield w


def test_true_joints_and_offsets(world):
    gt = GroundTruth(world)
    dq = gt.joint_offset("psm1")
    assert np.allclose(np.rad2deg(dq[:2]), [2.06, -2.29]) and dq[2] == pytest.approx(-0.003)
    assert np.all(dq[3:] == 0) and np.all(gt.joint_offset("psm2") == 0)
    # True joints = measured + offset (the encoders report q_actual − Δq).
    assert np.allclose(gt.joint_positions("psm1"), world.psm1.measured_jp() + dq)


def test_true_tip_pose_matches_the_pybullet_arm(world):
    gt = GroundTruth(world)
    for arm in ("psm1", "psm2"):
        assert np.allclose(gt.tip_pose_world(arm), world.arms[arm].body.tip_pose(), atol=1e-6)
        assert np.allclose(gt.tip_pose_base(arm), forward_kinematics(gt.joint_positions(arm)))
    # With an offset, the true tip differs from what the arm reports.
    reported = world.psm1.base_frame() @ world.psm1.measured_cp()
    assert np.linalg.norm(reported[:3, 3] - gt.tip_pose_world("psm1")[:3, 3]) > 2e-3


def test_needle_pose_and_scored_points(world):
    gt = GroundTruth(world)
    T = gt.needle_pose()
    assert gt.needle_holder() == "psm2"
    in_hand = invert(gt.tip_pose_world("psm2")) @ T
    assert np.allclose(in_hand, world.in_jaw_grasp_pose(), atol=1e-6)
    pts = gt.needle_scored_points()
    assert np.linalg.norm(pts["base"] - pts["tip"]) == pytest.approx(0.01794, abs=1e-5)
    cam = gt.needle_pose_in_camera("left")
    assert 0.02 < cam[2, 3] < 0.3  # in front of the left eye


def test_segmentation_masks(world):
    masks = GroundTruth(world).segmentation("left")
    assert masks["needle"].shape == (90, 160)
    assert masks["needle"].any() and masks["psm2_jaws"].any()
    assert not (masks["needle"] & masks["psm2"]).any()
    assert (masks["psm2_jaws"] <= masks["psm2"]).all()
