"""Laying a held needle down: a spot in view and in reach, jaws straight down, high enough."""

import numpy as np
import pytest
from skill_helpers import PHANTOMS, make_arm, make_ctx

from suture_bt.geometry.tissue_surface import height_above_tissue
from suture_bt.skills.grasps import GRASP_DEPTH
from suture_bt.skills.lay_down import RELEASE_CLEARANCE, LayDown, release_pose
from suture_bt.transforms import pose_to_transform

#: Phantom poses: default, moved and turned, tilted a few degrees (test_presentation's
#: "tilted", 11° and 6°, leaves no pick-up from above within the wrist's limits).
SCENES = {
    "default": PHANTOMS["default"],
    "moved": PHANTOMS["moved"],
    "tilted 3°": pose_to_transform((0.0, 0.005, 0.0), (0.05, 0.03, 0.05)),
}


@pytest.mark.parametrize("phantom", sorted(SCENES))
def test_the_spot_is_in_view_on_the_tissue_and_the_jaws_point_straight_down(phantom):
    ctx, arm = make_ctx(SCENES[phantom]), make_arm("psm2")
    arm.calibrated = True
    T_spot, T_release = LayDown(ctx, "psm2", np.deg2rad(150.0))._choose_spot(arm)
    up = ctx.phantom.T_world_phantom[:3, 2]
    assert T_release[:3, 2] @ up == pytest.approx(-1.0)  # jaws down: the needle lies level
    assert abs(height_above_tissue(ctx.phantom, T_spot[:3, 3][None])[0]) < 0.001
    pinch = T_release[:3, 3] - GRASP_DEPTH * T_release[:3, 2]
    height = height_above_tissue(ctx.phantom, pinch[None])[0]
    assert RELEASE_CLEARANCE - 1e-6 <= height < RELEASE_CLEARANCE + 0.001  # calibrated
    # The pinch point is one needle radius from the spot's centre (the jaw holds the wire).
    flat = (pinch - T_spot[:3, 3]) - ((pinch - T_spot[:3, 3]) @ up) * up
    assert np.linalg.norm(flat) == pytest.approx(ctx.needle.radius, abs=1e-6)


def test_an_uncalibrated_arm_lets_go_higher_by_its_possible_offsets():
    ctx, arm = make_ctx(), make_arm("psm2")
    T_spot, _ = LayDown(ctx, "psm2", np.deg2rad(150.0))._choose_spot(arm)
    high = release_pose(ctx, arm, T_spot)
    arm.calibrated = True
    low = release_pose(ctx, arm, T_spot)
    lift = (high[:3, 3] - low[:3, 3]) @ ctx.phantom.T_world_phantom[:3, 2]
    assert 0.005 < lift < 0.03  # the tip may be up to ~20 mm lower than its joints say


def test_an_arm_that_reaches_no_spot_fails_saying_why(monkeypatch):
    from suture_bt.skills import lay_down
    from suture_bt.skills.base import SkillFailure

    ctx, arm = make_ctx(), make_arm("psm2")
    monkeypatch.setattr(lay_down, "SPOTS_X", (0.5,))  # half a metre off: in no view
    with pytest.raises(SkillFailure, match="no spot on the tissue where psm2 can lay"):
        LayDown(ctx, "psm2", np.deg2rad(150.0))._choose_spot(arm)


def test_the_spot_keeps_the_needle_from_under_the_arms_calibration_jaw(monkeypatch):
    from suture_bt.skills import lay_down

    ctx, arm = make_ctx(), make_arm("psm2")
    jaw = lay_down.calibration_jaw_pixels(ctx, arm)
    assert len(jaw) == 27 * 4  # 4 keypoints over the offset box
    T_spot, _ = LayDown(ctx, "psm2", np.deg2rad(150.0))._choose_spot(arm)
    spot_px = ctx.camera.model.left.project(T_spot[:3, 3][None])
    gap = np.min(np.linalg.norm(jaw - spot_px, axis=1))
    assert gap > 2 * lay_down.JAW_VIEW_MARGIN_PX
    # Level with pair 3 on either side of the ridge: the entry side lies under the jaw in the
    # image, the exit side does not; a spot under the jaw is taken only when no other will do.
    monkeypatch.setattr(lay_down, "SPOTS_X", (-0.017, 0.022))
    monkeypatch.setattr(lay_down, "SPOTS_Y", (0.0,))
    lay = LayDown(ctx, "psm2", np.deg2rad(150.0))
    T_spot, _ = lay._choose_spot(arm)
    assert T_spot[0, 3] > 0.0 and lay.report["landing_share"] > 0.5
    monkeypatch.setattr(lay_down, "SPOTS_X", (-0.017,))
    lay = LayDown(ctx, "psm2", np.deg2rad(150.0))
    T_spot, _ = lay._choose_spot(arm)
    assert T_spot[0, 3] < 0.0 and lay.report["landing_share"] < 0.5  # mostly under the jaw
