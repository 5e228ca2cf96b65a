"""Insert's tip reading: where the frame shows the emerged tip along the predicted circle."""

from types import SimpleNamespace

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.planning import plan_needle_arc
from suture_bt.skills.context import NeedleNotSeen
from suture_bt.skills.insert import Insert
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


def reading(T_true, everywhere=False):
    ctx = SimpleNamespace(needle=NEEDLE, sensor=FrameOf(T_true, everywhere), arms={})
    skill = Insert(ctx, "psm2", 2)
    return skill._tip_reading(PLANNED, EXIT), skill


def along(T, deg):
    """``T`` advanced ``deg`` along the sweep (the sweep turns the needle about its −z)."""
    return T @ make_transform(rpy_to_matrix((0.0, 0.0, -np.deg2rad(deg))))


def test_a_needle_where_the_arm_says_is_read_within_a_few_degrees():
    (T, how), skill = reading(PLANNED)
    turn = skill.report["evidence"]["turn_deg"]
    assert -5.0 <= turn <= 0.0 and "along the arc" in how


@pytest.mark.parametrize("short_deg", [8.0, 13.5, 20.0])
def test_a_needle_short_along_its_arc_is_read_short_never_longer(short_deg):
    (T, _), skill = reading(along(PLANNED, -short_deg))
    turn = skill.report["evidence"]["turn_deg"]
    assert -short_deg - 5.0 <= turn <= -short_deg
    assert skill._tip_out(T, EXIT) < skill._tip_out(along(PLANNED, -short_deg), EXIT) + 1e-4


def test_no_metal_or_metal_everywhere_is_no_reading():
    assert reading(None)[0] is None  # no emerged tip in the frame
    assert reading(None, everywhere=True)[0] is None  # a jaw behind it: nothing ends anywhere


def test_a_needle_still_under_the_surface_is_no_reading():
    assert reading(along(PLANNED, -40.0))[0] is None
