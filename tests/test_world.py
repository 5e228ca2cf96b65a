"""World: simulated time, periodic callbacks, determinism, several worlds, closing."""

import numpy as np
import pytest

from suture_bt.interfaces import WorldInterface
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World, psm_base_frame


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
    assert isinstance(world, WorldInterface) or world.camera is None
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
