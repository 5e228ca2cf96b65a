"""Tissue entries: the world records every place the needle tip goes into the tissue (ground
truth), far from the ports as well as through them; a needle that starts inside records none."""

import numpy as np
import pytest

from suture_bt.control import PIServo
from suture_bt.geometry.phantom import TISSUE_TOP_Z, PhantomModel
from suture_bt.planning import (
    CartesianMove,
    PoseSequenceMove,
    gripper_poses,
    in_base,
    plan_needle_arc,
    to_base,
)
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.phantom_body import PhantomBody
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.transforms import invert, pose_to_transform


def _held_world() -> World:
    """PSM2 holds the needle at the Task-3 start; ideal servo (fast, exact moves)."""
    scene = scene_from_dict({"needle": {"start": "in_psm2_jaw"}, "servo": {"error_model": False}})
    return World.from_scene(scene, with_camera=False)


def _tip(truth: GroundTruth) -> np.ndarray:
    """The true needle tip (world)."""
    return truth.needle_scored_points()["tip"]


def test_fast_inside_check_matches_inside_tissue():
    """The tracker's plain-Python test is the same solid as ``inside_tissue`` (moved phantom)."""
    import pybullet as pb

    client = pb.connect(pb.DIRECT)
    try:
        T = pose_to_transform((0.01, -0.02, 0.005), (0.1, -0.05, 0.7))
        body = PhantomBody(client, PhantomModel(T))
        rng = np.random.default_rng(0)
        local = rng.uniform([-0.05, -0.06, 0.06], [0.05, 0.08, 0.09], (20000, 3))
        pts = local @ T[:3, :3].T + T[:3, 3]
        fast = np.array([body._point_inside(*q) for q in pts])
        assert np.array_equal(fast, body.inside_tissue(pts))
        assert 0.1 < fast.mean() < 0.6
    finally:
        pb.disconnect(client)


def test_held_needle_pushed_into_the_flat_tissue_away_from_ports():
    with _held_world() as w:
        truth = GroundTruth(w)
        # The exact tip (from the arm: between bookkeeping updates the needle body lags its
        # jaw by up to ~0.1 mm) at 1 kHz; a callback at t sees the state of t − 1 ms.
        T_tip_needle = invert(truth.tip_pose_world("psm2")) @ truth.needle_pose()
        tip_in_hand = T_tip_needle[:3, :3] @ w.task.needle.tip + T_tip_needle[:3, 3]
        path: list[tuple[float, np.ndarray]] = []

        def sample(t: float) -> None:
            T = truth.tip_pose_world("psm2")
            path.append((t - 0.001, T[:3, :3] @ tip_in_hand + T[:3, 3]))

        w.add_periodic(0.001, sample)
        tip0 = _tip(truth)
        assert tip0[2] > TISSUE_TOP_Z + 0.005 and truth.tissue_entries() == []
        goal = truth.tip_pose_world("psm2")
        goal[2, 3] -= tip0[2] - (TISSUE_TOP_Z - 0.005)  # the tip ends ~5 mm under the surface
        w.psm2.move_cp(invert(w.psm2.base_frame()) @ goal)
        while w.psm2.is_busy():
            w.step(0.1)
        w.step(0.05)
        entries = truth.tissue_entries()
        assert len(entries) == 1, entries
        e = entries[0]
        # Independent check on the 1 kHz tip path: the first sample inside the tissue.
        times = np.array([t for t, _ in path])
        tips = np.stack([q for _, q in path])
        k = int(np.argmax(w.phantom.inside_tissue(tips)))
        assert k > 0 and times[k - 1] <= e.t <= times[k]
        assert np.linalg.norm(e.point - tips[k]) < 2e-4
        assert e.point[2] == pytest.approx(TISSUE_TOP_Z, abs=1e-6)  # on the flat top face
        ports = w.task.phantom.ports()
        d = [np.linalg.norm(e.point - q.position) for q in ports]
        assert e.nearest_port == ports[int(np.argmin(d))].name
        assert e.distance == pytest.approx(min(d), abs=1e-9)
        assert e.distance > 0.005  # a stab, not a port
        deepest = np.linalg.norm(tips[k:] - e.point, axis=1).max()
        assert e.depth_max == pytest.approx(deepest, abs=2e-4)
        assert 0.004 < e.depth_max < 0.008
        # Staying inside adds nothing; released there, the tissue holds it: still one entry.
        w.psm2.jaw.open()
        w.step(0.3)
        assert w.needle.frozen and len(truth.tissue_entries()) == 1


def test_needle_starting_inside_the_tissue_records_no_entry():
    T = np.eye(4)
    T[:3, 3] = (0.025, -0.035, TISSUE_TOP_Z - 0.002)  # arc flat, 2 mm under the block top
    scene = scene_from_dict(
        {"needle": {"start": "pose", "position": T[:3, 3].tolist(), "rpy": [0.0, 0.0, 0.0]}}
    )
    with World.from_scene(scene, with_camera=False) as w:
        truth = GroundTruth(w)
        assert w.needle.frozen and w.phantom.inside_tissue(_tip(truth)[None])[0]
        w.step(0.2)
        assert truth.tissue_entries() == []


def test_needle_frozen_in_the_tissue_far_away_records_no_entry():
    with _held_world() as w:
        truth = GroundTruth(w)
        w.psm2.jaw.open()
        w.step(0.02)
        T = np.eye(4)
        T[:3, 3] = (0.025, -0.035, TISSUE_TOP_Z - 0.002)
        w.needle.freeze(T)  # set_pose + the tissue's hold, 60 mm from the last sample
        w.step(0.1)
        assert truth.tissue_entries() == []


def test_tracker_interpolates_skips_teleports_and_keeps_time_while_still():
    import pybullet as pb

    client = pb.connect(pb.DIRECT)
    try:
        body = PhantomBody(client, PhantomModel())
        top = TISSUE_TOP_Z
        assert body.track_tip((0.02, 0.0, top + 0.001), 0.0) is None  # first sample: state only
        body.track_tip(None, 1.0)  # still until t = 1 s
        e = body.track_tip((0.02, 0.0, top - 0.003), 1.004)
        assert e is not None and body.tissue_entries == [e]
        assert np.allclose(e.point, (0.02, 0.0, top), atol=1e-8)
        assert e.t == pytest.approx(1.001) and e.depth_max == pytest.approx(0.003)
        ports = body.phantom.ports()
        d = [np.linalg.norm(e.point - q.position) for q in ports]
        assert e.nearest_port == ports[int(np.argmin(d))].name
        assert e.distance == pytest.approx(min(d))
        body.track_tip((0.02, 0.0, top - 0.006), 1.008)  # deeper
        body.track_tip((0.02, 0.0, top - 0.004), 1.012)  # backing up: the maximum stays
        assert e.depth_max == pytest.approx(0.006)
        body.track_tip((0.02, 0.0, top + 0.002), 1.016)  # out
        body.track_tip((0.02, 0.0, top - 0.008), 1.020)  # a second entry, same place
        assert len(body.tissue_entries) == 2 and e.depth_max == pytest.approx(0.006)
        body.track_tip((0.02, 0.0, top + 0.002), 1.024)
        # A 30 mm jump into the tissue is a teleport, not a motion.
        assert body.track_tip((0.02, 0.03, top - 0.002), 1.028) is None
        body.track_tip((0.02, 0.03, top + 0.002), 1.032)
        body.reset_entry_tracking()
        assert body.track_tip((0.02, 0.03, top - 0.002), 1.036) is None
        assert len(body.tissue_entries) == 2
    finally:
        pb.disconnect(client)


def test_released_needle_landing_on_the_tissue_is_not_an_entry():
    with _held_world() as w:
        w.psm2.jaw.open()
        w.step(1.5)
        assert w.needle.is_resting() and GroundTruth(w).tissue_entries() == []


def _insert(world: World, pair: int) -> None:
    """Approach and planned insertion with PSM2 (as tests/test_motion_integration.py)."""
    truth = GroundTruth(world)
    servo = PIServo(world.psm2)
    servo.reset()
    servo.attach(world.add_periodic)
    T_gn = invert(truth.tip_pose_world("psm2")) @ truth.needle_pose()
    arc = plan_needle_arc(*world.task.phantom.pair(pair), world.task.needle)
    base = world.psm2.base_frame()
    goals = [to_base(T @ invert(T_gn), base) for T in arc.approach_poses(0.006, 0.010)]
    seq = in_base(
        gripper_poses(
            arc.insertion(
                start_angle=arc.pre_insertion_angle(0.006), angular_speed=0.6, angular_acc=2.4
            ),
            T_gn,
        ),
        base,
    )
    for move in (
        CartesianMove(servo, goals, v_lin=0.08, a_lin=0.4, v_ang=1.2, a_ang=4.0),
        PoseSequenceMove(servo, seq.times, seq.poses),
    ):
        st = move.start()
        assert not st.failed, st.reason
        servo.follow(move)
        for _ in range(400):
            if move.status.done or move.status.failed:
                break
            world.step(0.05)
        assert move.status.done, move.status.reason
        world.step(0.2)


@pytest.mark.parametrize("pair", [2, 4])
def test_planned_insertion_enters_at_its_entry_port(pair):
    scene = scene_from_dict(
        {
            "servo": {"error_model": True},
            "needle": {"start": "in_psm2_jaw", "grasp_arc_angle_deg": 155.0},
        }
    )
    with World.from_scene(scene, with_camera=False) as w:
        _insert(w, pair)
        truth = GroundTruth(w)
        entries = truth.tissue_entries()
        assert len(entries) == 1, entries
        e = entries[0]
        assert e.nearest_port == f"entry{pair}" and e.distance < 2.5e-3
        crossing = next(c for c in truth.port_crossings() if c.port == f"entry{pair}")
        assert e.t == pytest.approx(crossing.t, abs=0.005)
        assert 0.005 < e.depth_max < 0.012  # under the ridge, at most a chord of the needle
