"""Tip reading: where the frame shows the emerged tip near the predicted pose."""

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.planning import plan_needle_arc
from suture_bt.skills.context import NeedleNotSeen
from suture_bt.skills.grasps import GRASP_DEPTH, hand, tip_goal
from suture_bt.skills.tip_reading import pivoted, read_tip, tip_out
from suture_bt.transforms import make_transform, rpy_to_matrix

NEEDLE = NeedleModel()
ARC = plan_needle_arc(*PhantomModel().pair(2), NEEDLE)
EXIT = ARC.exit
PLANNED = ARC.needle_pose(ARC.insert_end_angle)


class FrameOf:
    """A sensor whose frame shows metal along a true needle's centre-line (or everywhere,
    or nowhere) and whose localiser always refuses."""

    def __init__(self, T_true: np.ndarray | None, everywhere: bool = False):
        self.T_true, self.everywhere = T_true, everywhere

    def observe(self, *args, **kwargs):
        raise NeedleNotSeen("refused")

    def hits(self, T_world_needle, angles):
        n = len(angles)
        if self.everywhere or self.T_true is None:
            h = np.full(n, self.everywhere)
            return h, h.copy()
        pts = NEEDLE.point_at(np.asarray(angles)) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
        line = NEEDLE.point_at(np.linspace(NEEDLE.tip_angle, NEEDLE.base_angle, 400))
        true = line @ self.T_true[:3, :3].T + self.T_true[:3, 3]
        h = np.min(np.linalg.norm(pts[:, None] - true[None], axis=2), axis=1) < 3e-4
        return h, h.copy()


#: The insertion grasp at the planned end (160° along the arc): its pinch point (the wire sits
#: GRASP_DEPTH behind the tip) and closing axis (tip y, normal to the blade faces).
GRIP = tip_goal(PLANNED, hand(NEEDLE, np.deg2rad(160.0)))
JAW = (GRIP[:3, 3] - GRASP_DEPTH * GRIP[:3, 2], GRIP[:3, 1])


def reading(T_true, everywhere=False, jaw=JAW):
    return read_tip(FrameOf(T_true, everywhere), NEEDLE, PLANNED, EXIT, jaw)


def along(T, deg):
    """``T`` advanced ``deg`` along the sweep (the sweep turns the needle about its −z)."""
    return T @ make_transform(rpy_to_matrix((0.0, 0.0, -np.deg2rad(deg))))


def test_a_needle_where_the_arm_says_is_read_within_a_few_degrees():
    r = reading(PLANNED)
    assert -5.0 <= r.turn_deg <= 0.0 and r.pivot_deg == 0.0 and "along the arc" in r.describe()


@pytest.mark.parametrize("short_deg", [8.0, 13.5, 20.0])
def test_a_needle_short_along_its_arc_is_read_short_never_longer(short_deg):
    true = along(PLANNED, -short_deg)
    r = reading(true)
    assert -short_deg - 5.0 <= r.turn_deg <= -short_deg and r.pivot_deg == 0.0
    assert tip_out(r.T_world_needle, NEEDLE, EXIT) < tip_out(true, NEEDLE, EXIT) + 1e-4


@pytest.mark.parametrize("pivot", [-4.5, 3.0, 7.7])
def test_a_needle_that_slipped_in_the_jaw_is_read_on_its_tilted_circle(pivot):
    # As the world's slips turn it: about the jaw's closing axis through the pinch point (a
    # campaign trial's two slips, mid-move then on contact, added up to 7.7°).
    true = along(pivoted(PLANNED, JAW[0], pivot, JAW[1]), -6.0)
    r = reading(true)
    assert r is not None and r.pivot_deg == pytest.approx(pivot, abs=1.6)
    assert np.linalg.norm(r.T_world_needle[:3, 3] - true[:3, 3]) < 0.0006
    assert reading(true, jaw=None) is None  # on the predicted circle alone: no reading


def test_no_metal_or_metal_everywhere_is_no_reading():
    assert reading(None) is None  # no emerged tip in the frame
    assert reading(None, everywhere=True) is None  # a jaw behind it: nothing ends anywhere


def test_a_needle_still_under_the_surface_is_no_reading():
    assert reading(along(PLANNED, -40.0)) is None


class HangingFrameOf:
    """A frame showing metal where a needle held by the tissue is in the open: along its
    centre-line above the phantom's surface, overshooting each end by ``overshoot_deg`` (as
    measured in the simulation's frames)."""

    def __init__(self, T_true: np.ndarray | None, overshoot_deg: float = 6.0):
        self.T_true, self.over = T_true, np.deg2rad(overshoot_deg)

    def hits(self, T_world_needle, angles):
        from suture_bt.geometry.tissue_surface import height_above_tissue

        angles = np.asarray(angles)
        if self.T_true is None:
            return np.zeros(len(angles), bool), np.zeros(len(angles), bool)
        pts = NEEDLE.point_at(angles) @ T_world_needle[:3, :3].T + T_world_needle[:3, 3]
        a = np.linspace(NEEDLE.tip_angle - self.over, NEEDLE.base_angle + self.over, 600)
        true = NEEDLE.point_at(a) @ self.T_true[:3, :3].T + self.T_true[:3, 3]
        on = np.min(np.linalg.norm(pts[:, None] - true[None], axis=2), axis=1) < 3e-4
        h = on & (height_above_tissue(PhantomModel(), pts) > 0.0)
        return h, h.copy()


@pytest.mark.parametrize("phi_deg, lag_deg", [(30.0, 3.0), (60.0, -8.0), (90.0, 20.0)])
def test_a_needle_held_by_the_tissue_is_read_along_the_circle_it_was_held_on(phi_deg, lag_deg):
    from suture_bt.skills.tip_reading import read_hanging

    true = ARC.needle_pose(np.deg2rad(phi_deg))  # dropped part way through pair 2
    predicted = along(true, lag_deg)  # the arm swept on (or less far) before it knew
    r = read_hanging(HangingFrameOf(true), NEEDLE, PhantomModel(), predicted)
    assert r is not None and r.turn_deg == pytest.approx(-lag_deg, abs=2.5)  # back to it
    assert np.linalg.norm(r.T_world_needle[:3, 3] - true[:3, 3]) < 1e-6  # same centre


def test_no_needle_where_it_was_held_is_no_hanging_reading():
    from suture_bt.skills.tip_reading import read_hanging

    gone = read_hanging(HangingFrameOf(None), NEEDLE, PhantomModel(), PLANNED)
    assert gone is None  # it fell: nothing in the open along its circle
