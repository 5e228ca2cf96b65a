"""World: simulated time, periodic callbacks, determinism, several worlds, closing."""

import numpy as np
import pytest

from suture_bt.geometry.phantom import TISSUE_TOP_Z
from suture_bt.interfaces import WorldInterface
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World, psm_base_frame
from suture_bt.transforms import invert


@pytest.fixture
def world():
    with World.from_scene() as w:
        yield w


def test_step_advances_simulated_time_in_ticks(world):
    world.step(0.0106)
    assert world.clock.now() == pytest.approx(0.011)  # rounded to whole 1 ms ticks
    world.step(0.0094)
    assert world.clock.now() == pytest.approx(0.020)
    with pytest.raises(ValueError):
        world.step(-1.0)


def test_periodic_callbacks_run_at_their_rate_in_order(world):
    calls = []
    h1 = world.add_periodic(0.002, lambda t: calls.append(("a", round(t, 6))))
    world.add_periodic(0.004, lambda t: calls.append(("b", round(t, 6))))
    world.step(0.008)
    assert [c for c in calls if c[0] == "a"] == [("a", 0.001 * k) for k in (1, 3, 5, 7)]
    assert [c for c in calls if c[0] == "b"] == [("b", 0.001), ("b", 0.005)]
    assert calls.index(("a", 0.005)) < calls.index(("b", 0.005))
    world.remove_periodic(h1)
    n = len(calls)
    world.step(0.004)
    assert all(c[0] == "b" for c in calls[n:])
    with pytest.raises(ValueError):
        world.remove_periodic(h1)
    with pytest.raises(ValueError, match="multiple"):
        world.add_periodic(0.0015, lambda t: None)


def test_periodic_callback_sees_arm_and_can_command_it(world):
    q0 = world.psm1.measured_jp()

    def servo(t):
        world.psm1.servo_jp(q0 + np.array([0.05 * t, 0, 0, 0, 0, 0]))

    world.add_periodic(0.005, servo)
    world.step(0.5)
    assert world.psm1.setpoint_jp()[0] > q0[0]


def test_same_scene_same_run():
    scene = scene_from_dict({"seed": 3, "arms": {"psm1": {"joint_offset": "random"}}})
    results = []
    for _ in range(2):
        with World.from_scene(scene) as w:
            w.psm1.move_jp(w.psm1.setpoint_jp() + 0.1)
            w.step(0.3)
            results.append((w.psm1.measured_jp(), w.psm1.body.tip_pose()))
    assert np.array_equal(results[0][0], results[1][0])
    assert np.array_equal(results[0][1], results[1][1])


def test_worlds_coexist_and_close(world):
    other = World.from_scene(scene_from_dict({"servo": {"error_model": False}}))
    assert other.client != world.client
    other.psm1.servo_jp(other.psm1.setpoint_jp() + 0.05)
    other.step(0.01)
    world.step(0.01)
    assert not np.allclose(other.psm1.body.tip_pose(), world.psm1.body.tip_pose())
    other.close()
    other.close()  # idempotent
    with pytest.raises(RuntimeError):
        other.step(0.01)
    world.step(0.01)  # the first world still works


def test_world_interface_and_base_frames(world):
    assert isinstance(world, WorldInterface)
    assert (world.camera.width, world.camera.height) == (1920, 1080)
    assert np.allclose(world.psm1.base_frame()[:3, 3], (0.1, 0.1346, 0.135))
    assert np.allclose(world.psm2.base_frame(), psm_base_frame("psm2"))


def test_task_follows_the_scene_phantom_pose():
    scene = scene_from_dict({"phantom": {"position": [0.01, -0.02, 0.003], "rpy": [0, 0, 0.3]}})
    with World.from_scene(scene) as w:
        p = w.task.phantom.port("entry1").position
        default = World.from_scene()
        q = default.task.phantom.port("entry1").position
        default.close()
        assert np.linalg.norm(p - q) > 5e-3
        assert np.allclose(w.task.phantom.T_world_phantom[:3, 3], (0.01, -0.02, 0.003))


def _held_scene(**extra):
    return scene_from_dict(
        {"needle": {"start": "in_psm2_jaw"}, "servo": {"error_model": False}, **extra}
    )


def _wire_grasp_goal(T_world_needle, model, arc_deg):
    """Tip pose with the wire at arc_deg running between PSM1's blades (a reachable variant)."""
    a = np.deg2rad(arc_deg)
    goal = np.eye(4)
    goal[:3, 0] = -(T_world_needle[:3, :3] @ model.tangent_at(a))
    goal[:3, 2] = T_world_needle[:3, 2]
    goal[:3, 1] = np.cross(goal[:3, 2], goal[:3, 0])
    goal[:3, 3] = T_world_needle[:3, :3] @ model.point_at(a) + T_world_needle[:3, 3]
    return goal


def test_needle_starts_in_psm2_jaw_and_follows_it():
    with World.from_scene(_held_scene(), with_camera=False) as w:
        gt = GroundTruth(w)
        assert gt.needle_holder() == "psm2"
        assert 0 < w.psm2.jaw.measured_jp()[0] <= 0.2  # blades rest on the wire
        in_hand = invert(gt.tip_pose_world("psm2")) @ gt.needle_pose()
        w.psm2.move_jp(w.psm2.setpoint_jp() + np.array([0.1, 0.05, 0.01, 0.2, 0.1, 0.1]))
        w.step(0.8)
        assert not w.psm2.is_busy()
        after = invert(gt.tip_pose_world("psm2")) @ gt.needle_pose()
        assert np.allclose(after, in_hand, atol=1e-6)


def test_handover_grasp_geometry_and_release():
    with World.from_scene(_held_scene(), with_camera=False) as w:
        gt = GroundTruth(w)
        goal = _wire_grasp_goal(gt.needle_pose(), w.task.needle, 80.0)
        # Closing far from the needle grasps nothing.
        w.psm1.jaw.open()
        w.step(0.6)
        w.psm1.jaw.close()
        w.step(0.6)
        assert gt.needle_holder() == "psm2"
        assert not w.last_grasp["psm1"].ok and "mm" in w.last_grasp["psm1"].reason
        # Closing with the wire between the blades grasps it: a handover.
        w.psm1.jaw.open()
        w.psm1.move_cp(invert(w.psm1.base_frame()) @ goal)
        while w.psm1.is_busy():
            w.step(0.1)
        T_before = gt.needle_pose()
        w.psm1.jaw.close()
        w.step(0.8)
        assert w.last_grasp["psm1"].ok, w.last_grasp["psm1"].reason
        assert gt.needle_holders() == ["psm2", "psm1"]
        # The in-hand pose is what the geometry gives: the needle did not jump.
        assert np.linalg.norm(gt.needle_pose()[:3, 3] - T_before[:3, 3]) < 1.6e-3
        w.psm2.jaw.open()
        w.step(0.2)
        assert gt.needle_holders() == ["psm1"]
        in_hand = invert(gt.tip_pose_world("psm1")) @ gt.needle_pose()
        w.psm1.move_jp(w.psm1.setpoint_jp() + np.array([0.05, 0.05, -0.01, 0, 0, 0]))
        w.step(0.5)
        assert np.allclose(invert(gt.tip_pose_world("psm1")) @ gt.needle_pose(), in_hand, atol=1e-6)
        # Opening the last jaw releases the needle.
        w.psm1.jaw.open()
        w.step(0.05)
        assert gt.needle_holder() is None


def test_released_needle_falls_and_rests_on_the_tissue():
    with World.from_scene(_held_scene(), with_camera=False) as w:
        gt = GroundTruth(w)
        z0 = gt.needle_pose()[2, 3]
        w.psm2.jaw.open()
        w.step(0.1)
        assert gt.needle_holder() is None
        assert gt.needle_pose()[2, 3] < z0 - 0.01  # free fall: ~ g t² / 2 = 49 mm
        w.step(1.4)
        assert w.needle.is_resting()
        pts = w.task.needle.centerline(40) @ gt.needle_pose()[:3, :3].T + gt.needle_pose()[:3, 3]
        # It lies on the tissue: the lowest wire point at the surface, nothing inside it.
        assert pts[:, 2].min() == pytest.approx(TISSUE_TOP_Z + 0.00036, abs=0.0004)
        assert not w.phantom.inserted(gt.needle_pose())


def test_released_inserted_needle_stays():
    with World.from_scene(_held_scene(), with_camera=False) as w:
        gt = GroundTruth(w)
        goal = gt.tip_pose_world("psm2")
        goal[2, 3] -= 0.028  # push the hanging needle into the tissue block
        w.psm2.move_cp(invert(w.psm2.base_frame()) @ goal)
        while w.psm2.is_busy():
            w.step(0.1)
        T_in = gt.needle_pose()
        assert w.phantom.inserted(T_in)
        w.psm2.jaw.open()
        w.step(0.5)
        assert gt.needle_holder() is None and w.needle.frozen
        assert np.allclose(gt.needle_pose(), T_in, atol=1e-6)


def test_resting_start_follows_a_moved_phantom():
    scene = scene_from_dict({"phantom": {"position": [0.01, 0.005, 0.002], "rpy": [0.0, 0.0, 0.4]}})
    with World.from_scene(scene, with_camera=False) as w:
        w.step(0.3)
        T = GroundTruth(w).needle_pose()
        expected = w.task.phantom.T_world_phantom[:3, :3] @ (-0.0208, 0.0562, 0.0717)
        expected += w.task.phantom.T_world_phantom[:3, 3]
        assert np.linalg.norm(T[:3, 3] - expected) < 1e-3
        assert w.needle.is_resting()


def test_a_throw_records_src_crossings_and_tip_out():
    """PSM2 drives the held needle along the planned arc of pair 1 (ideal servo, no offset)."""
    from suture_bt.planning.needle_arc import gripper_poses, in_base, plan_needle_arc

    with World.from_scene(_held_scene(), with_camera=False) as w:
        gt = GroundTruth(w)
        entry, exit_ = w.task.phantom.pair(1)
        arc = plan_needle_arc(entry, exit_, w.task.needle)
        T_tip_needle = invert(gt.tip_pose_world("psm2")) @ gt.needle_pose()
        needle_poses = arc.sweep(-0.3, arc.insert_end_angle, angular_speed=1.0, dt=0.01)
        goals = in_base(gripper_poses(needle_poses, T_tip_needle), w.psm2.base_frame())
        w.psm2.move_cp(goals.poses[0])
        while w.psm2.is_busy():
            w.step(0.1)
        previous = 0.0
        for t, goal in zip(goals.times, goals.poses, strict=True):
            w.step(t - previous)
            previous = t
            w.psm2.servo_cp(goal)
        w.step(0.01)
        crossings = gt.port_crossings()
        assert [(c.port, c.src_direction) for c in crossings] == [
            ("entry1", True),
            ("exit1", True),
        ]
        assert all(c.lateral < 1e-4 for c in crossings)
        assert crossings[1].tip_out >= 0.005
        assert set(gt.phantom_state().strain) == {"entry1", "exit1"}


def test_explicit_needle_pose_and_random_offsets_from_the_scene():
    scene = scene_from_dict(
        {
            "seed": 11,
            "needle": {"start": "pose", "position": [0.0, 0.0, 0.09], "rpy": [0.3, 0.0, 0.2]},
            "arms": {"psm1": {"joint_offset": "random"}, "psm2": {"joint_offset": "random"}},
        }
    )
    with World.from_scene(scene, with_camera=False) as w:
        gt = GroundTruth(w)
        assert np.allclose(gt.needle_pose(), scene.needle.T_world_needle, atol=1e-9)
        assert np.array_equal(gt.joint_offset("psm1"), scene.joint_offset("psm1"))
        assert not np.array_equal(gt.joint_offset("psm1"), gt.joint_offset("psm2"))
        # The arms start where the scene says, as far as their encoders can tell.
        assert np.allclose(w.psm2.measured_jp(), scene.arms["psm2"].initial_jp)


def test_pick_up_a_resting_needle_lift_and_drop_it():
    with World.from_scene(scene_from_dict({"servo": {"error_model": False}})) as w:
        gt = GroundTruth(w)
        w.step(2.5)  # the needle comes to rest (and may fall asleep)
        T_rest = gt.needle_pose()
        goal = np.eye(4)
        a = np.deg2rad(150.0)
        goal[:3, 0] = -(T_rest[:3, :3] @ w.task.needle.tangent_at(a))
        goal[:3, 2] = -T_rest[:3, 2]  # jaws point down into the tissue
        goal[:3, 1] = np.cross(goal[:3, 2], goal[:3, 0])
        goal[:3, 3] = T_rest[:3, :3] @ w.task.needle.point_at(a) + T_rest[:3, 3]
        above = goal.copy()
        above[2, 3] += 0.01
        base = invert(w.psm2.base_frame())
        w.psm2.jaw.open()
        for g in (above, goal):
            w.psm2.move_cp(base @ g)
            while w.psm2.is_busy():
                w.step(0.1)
        w.psm2.jaw.close()
        w.step(0.8)
        assert gt.needle_holder() == "psm2", w.last_grasp["psm2"].reason
        w.psm2.move_cp(base @ above)
        while w.psm2.is_busy():
            w.step(0.1)
        assert gt.needle_pose()[2, 3] > T_rest[2, 3] + 0.008  # lifted with the jaw
        w.psm2.jaw.open()
        w.step(1.5)
        assert gt.needle_holder() is None
        assert gt.needle_pose()[2, 3] == pytest.approx(T_rest[2, 3], abs=1e-3)  # back down
