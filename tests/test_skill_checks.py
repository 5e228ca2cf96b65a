"""Skill confirmations: each says yes in its good case and NO where it must (no yes-only check)."""

import numpy as np
import pytest

from suture_bt.geometry import NeedleModel, PhantomModel
from suture_bt.planning import plan_needle_arc
from suture_bt.skills import checks
from suture_bt.skills.checks import (
    clear_of_tissue,
    jaw_holds_wire,
    poses_agree,
    tip_out_past_exit,
)
from suture_bt.transforms import make_transform, pose_to_transform, rpy_to_matrix

NEEDLE = NeedleModel()
MOVED = pose_to_transform((0.03, -0.02, 0.0), (0.0, 0.0, 0.26))
PHANTOMS = {"default": PhantomModel(), "moved": PhantomModel(MOVED)}


def _arc(phantom: str, pair: int):
    return plan_needle_arc(*PHANTOMS[phantom].pair(pair), NEEDLE)


# ------------------------------------------------------------------ jaw_holds_wire
def test_jaw_on_wire_says_yes():
    ok, detail = jaw_holds_wire(0.08)
    assert ok is True
    assert "wire" in detail


@pytest.mark.parametrize("angle", [0.0, 0.01, checks.JAW_ON_WIRE_MIN - 1e-4])
def test_jaw_closed_empty_says_no(angle):
    ok, detail = jaw_holds_wire(angle)
    assert ok is False
    assert "empty" in detail


@pytest.mark.parametrize("angle", [0.8, 1.5])
def test_jaw_open_says_no(angle):
    ok, _ = jaw_holds_wire(angle)
    assert ok is False


# ------------------------------------------------------------------ poses_agree
@pytest.fixture
def T_seen():
    return make_transform(rpy_to_matrix((0.3, -0.7, 1.9)), (0.01, 0.05, 0.08))


def test_same_pose_agrees(T_seen):
    ok, detail = poses_agree(T_seen, T_seen.copy())
    assert ok is True
    assert "0.0 mm / 0.0°" in detail


def test_small_error_within_tolerance_agrees(T_seen):
    T = T_seen.copy()
    T[:3, 3] += 0.002 * np.array([0.6, 0.0, 0.8])
    T[:3, :3] = T[:3, :3] @ rpy_to_matrix((np.deg2rad(5.0), 0.0, 0.0))
    assert poses_agree(T, T_seen)[0] is True


def test_5mm_off_disagrees(T_seen):
    T = T_seen.copy()
    T[:3, 3] += 0.005 * np.array([0.0, 0.6, -0.8])
    ok, detail = poses_agree(T, T_seen)
    assert ok is False
    assert "5.0 mm" in detail


def test_30deg_off_disagrees(T_seen):
    T = T_seen.copy()
    T[:3, :3] = T[:3, :3] @ rpy_to_matrix((0.0, np.deg2rad(30.0), 0.0))
    ok, detail = poses_agree(T, T_seen)
    assert ok is False
    assert "30.0°" in detail


# ------------------------------------------------------------------ stayed_in_place
def test_a_turn_within_the_needle_plane_still_counts_as_staying(T_seen):
    T = T_seen.copy()
    T[:3, :3] = T[:3, :3] @ rpy_to_matrix((0.0, 0.0, np.deg2rad(15.0)))  # about needle z
    ok, detail = checks.stayed_in_place(T, T_seen)
    assert ok is True and "plane turned 0.0°" in detail


def test_a_needle_moved_5mm_did_not_stay(T_seen):
    T = T_seen.copy()
    T[:3, 3] += np.array([0.0, 0.0, -0.005])  # fell
    ok, detail = checks.stayed_in_place(T, T_seen)
    assert ok is False and "5.0 mm away" in detail


def test_a_needle_whose_plane_tipped_did_not_stay(T_seen):
    T = T_seen.copy()
    T[:3, :3] = T[:3, :3] @ rpy_to_matrix((np.deg2rad(25.0), 0.0, 0.0))
    ok, detail = checks.stayed_in_place(T, T_seen)
    assert ok is False and "turned 25.0°" in detail


# ------------------------------------------------------------------ tip_out_past_exit
@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_planned_insertion_end_is_tip_out(phantom, pair):
    arc = _arc(phantom, pair)
    ok, detail, numbers = tip_out_past_exit(arc.needle_pose(arc.insert_end_angle), NEEDLE, arc.exit)
    assert ok is True, detail
    assert numbers["tip_out_mm"] >= 5.0
    assert numbers["lateral_mm"] <= 2.5
    assert arc.exit.name in detail


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
@pytest.mark.parametrize("pair", [1, 4])
def test_tip_under_surface_is_not_out(phantom, pair):
    arc = _arc(phantom, pair)
    ok, detail, numbers = tip_out_past_exit(arc.needle_pose(arc.port_angle * 0.8), NEEDLE, arc.exit)
    assert ok is False
    assert "under" in detail and numbers == {}


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_lateral_miss_is_not_out(phantom):
    arc = _arc(phantom, 2)
    T = arc.needle_pose(arc.insert_end_angle).copy()
    T[:3, 3] += 0.004 * arc.exit.T[:3, 0]  # 4 mm along the exit port's x
    ok, detail, numbers = tip_out_past_exit(T, NEEDLE, arc.exit)
    assert ok is False, detail
    assert numbers["lateral_mm"] == pytest.approx(4.0, abs=0.05)
    assert numbers["tip_out_mm"] >= 5.0  # only the lateral rule fails


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_tip_only_2mm_out_is_not_out(phantom):
    arc = _arc(phantom, 3)
    phis = np.linspace(arc.port_angle, arc.insert_end_angle, 2000)
    outs = []
    for phi in phis:
        res = tip_out_past_exit(arc.needle_pose(phi), NEEDLE, arc.exit)
        outs.append(res[2].get("tip_out_mm", -1.0))
    phi = phis[int(np.argmin(np.abs(np.array(outs) - 2.0)))]
    ok, detail, numbers = tip_out_past_exit(arc.needle_pose(phi), NEEDLE, arc.exit)
    assert numbers["tip_out_mm"] == pytest.approx(2.0, abs=0.1)
    assert numbers["lateral_mm"] <= 2.5  # only the tip-out rule fails
    assert ok is False, detail


def test_needle_that_never_reaches_exit_plane_is_not_out():
    arc = _arc("moved", 1)
    T = arc.needle_pose(0.0).copy()
    T[:3, 3] += 0.03 * arc.exit.normal  # the whole needle far above the exit plane
    ok, detail, _ = tip_out_past_exit(T, NEEDLE, arc.exit)
    assert ok is False
    assert "does not pass through" in detail


def test_other_pairs_exit_is_not_this_throw():
    """A needle through exit2 does not count as tip out past exit1 (4 pairs ≥ 23 mm apart)."""
    arc = _arc("moved", 2)
    other = PHANTOMS["moved"].port("exit1")
    ok, _, _ = tip_out_past_exit(arc.needle_pose(arc.insert_end_angle), NEEDLE, other)
    assert ok is False


# ------------------------------------------------------------------ clear_of_tissue
def _clear(phantom: str, T):
    ph = PHANTOMS[phantom]
    return clear_of_tissue(T, NEEDLE, ph.T_world_phantom, ph.ports())


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
@pytest.mark.parametrize("pair", [1, 3])
def test_needle_20mm_above_ports_is_clear(phantom, pair):
    arc = _arc(phantom, pair)
    up = PHANTOMS[phantom].T_world_phantom[:3, 2]
    T = arc.needle_pose(arc.insert_end_angle).copy()
    lowest = np.min((NEEDLE.centerline(60) @ T[:3, :3].T + T[:3, 3] - arc.exit.position) @ up)
    T[:3, 3] += (0.02 - lowest) * up  # lowest needle point 20 mm above the exit port
    ok, detail = _clear(phantom, T)
    assert ok is True, detail


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_needle_mid_insertion_is_not_clear(phantom, pair):
    arc = _arc(phantom, pair)
    ok, detail = _clear(phantom, arc.needle_pose(arc.port_angle / 2))
    assert ok is False, detail


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_needle_tip_just_in_entry_is_not_clear(phantom):
    arc = _arc(phantom, 2)
    ok, _ = _clear(phantom, arc.needle_pose(0.15))
    assert ok is False


@pytest.mark.parametrize("phantom", sorted(PHANTOMS))
def test_needle_sunk_below_flat_top_is_not_clear(phantom):
    """Far from the ridge (above a flank plane) but under the flat tissue top."""
    ph = PHANTOMS[phantom]
    T = ph.T_world_phantom @ make_transform(None, (-0.03, 0.01, 0.060))
    ok, detail = _clear(phantom, T)
    assert ok is False
    assert "needle -" in detail


def test_phantom_pose_is_used_not_default():
    """The same needle pose is judged against the phantom pose it is given."""
    arc = _arc("default", 2)
    T = arc.needle_pose(arc.port_angle / 2)
    assert _clear("default", T)[0] is False
    low = PhantomModel(make_transform(None, (0.0, 0.0, -0.010)))  # phantom 10 mm lower
    assert clear_of_tissue(T, NEEDLE, low.T_world_phantom, low.ports())[0] is True
    # And the moved phantom's own mid-insertion pose is inside the moved phantom only.
    arc_m = _arc("moved", 2)
    T_m = arc_m.needle_pose(arc_m.port_angle / 2)
    assert _clear("moved", T_m)[0] is False
    assert _clear("default", T_m)[0] is True
