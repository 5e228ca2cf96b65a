"""Faults in the world: each forced fault observably happens; scene faults are seeded."""

import numpy as np
import pytest

from suture_bt.interfaces import FrameLost
from suture_bt.sim.fault_config import profile, profile_names
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.scene import SceneError, default_scene, scene_from_dict
from suture_bt.sim.world import World

SMALL_CAMERA = {"width": 160, "height": 120}


def held_world(**overrides) -> World:
    return World.from_scene(
        scene_from_dict({"needle": {"start": "in_psm2_jaw"}, **overrides}), with_camera=False
    )


def test_no_faults_section_means_no_faults():
    assert default_scene().faults == profile("none")
    with held_world() as w:
        assert not w.faults.active
        w.step(0.2)
        assert GroundTruth(w).fault_events() == []


def test_slip_turns_and_slides_the_needle_in_the_jaw():
    with held_world() as w:
        gt = GroundTruth(w)
        tip_in_hand = np.linalg.inv(gt.tip_pose_world("psm2")) @ np.r_[gt.needle_tip(), 1]
        ev = w.faults.slip(angle_deg=4.0, slide_mm=1.0)
        w.step(0.05)
        assert gt.needle_holder() == "psm2"  # still held, elsewhere in the jaw
        moved = np.linalg.inv(gt.tip_pose_world("psm2")) @ np.r_[gt.needle_tip(), 1]
        assert 1.0e-3 < np.linalg.norm(moved - tip_in_hand) < 3e-3
        assert ev.kind == "slip" and ev.params["slide_mm"] == pytest.approx(1.0)
        before, after = ev.params["held_arc_deg"]
        assert before - after == pytest.approx(np.rad2deg(1e-3 / w.task.needle.radius))
        assert gt.fault_events() == [ev]


def test_drop_lets_the_needle_fall_and_the_jaw_close_on_nothing():
    with held_world() as w:
        gt = GroundTruth(w)
        z0 = gt.needle_pose()[2, 3]
        w.faults.drop()
        w.step(1.0)
        assert gt.needle_holder() is None
        assert gt.needle_pose()[2, 3] < z0 - 0.01  # fell onto the tissue
        assert w.psm2.jaw.measured_jp()[0] < 0.01  # the measured jaw shows it: closed empty
        assert [e.kind for e in gt.fault_events()] == ["drop"]


def test_slip_or_drop_now_without_a_held_needle_raises_and_waits_when_scheduled():
    with World.from_scene(scene_from_dict({}), with_camera=False) as w:
        with pytest.raises(RuntimeError, match="no arm holds the needle"):
            w.faults.drop()
        w.faults.drop(at=0.01)
        w.step(0.1)
        assert w.faults.pending() == [(0.01, "drop")]


def test_camera_faults_lost_dark_and_lighting():
    scene = scene_from_dict({"camera": SMALL_CAMERA})
    with World.from_scene(scene) as w:
        normal = w.camera.capture().left.mean()
        w.faults.lose_frames(2)
        for _ in range(2):
            with pytest.raises(FrameLost) as info:
                w.camera.capture()
            assert "lost" in info.value.reason and info.value.stamp == 0.0
        assert w.camera.capture().left.mean() == pytest.approx(normal)
        w.faults.darken(frames=1, brightness=0.2)
        assert w.camera.capture().left.mean() < 0.3 * normal
        w.faults.change_lighting(0.5, brightness=1.3, tilt_deg=20.0, at=0.1)
        w.step(0.2)
        assert w.camera.capture().left.mean() > 1.1 * normal
        w.step(0.5)
        assert w.camera.capture().left.mean() == pytest.approx(normal, rel=1e-3)  # back
        kinds = [e.kind for e in GroundTruth(w).fault_events()]
        assert kinds == ["frame_lost", "frame_lost", "dark", "lighting"]


def test_drift_moves_the_joint_and_not_the_reading():
    scene = scene_from_dict({"servo": {"error_model": False}})
    with World.from_scene(scene, with_camera=False) as w:
        gt = GroundTruth(w)
        q0, m0 = gt.joint_positions("psm1"), w.psm1.measured_jp()
        w.faults.drift("psm1", (0.5, -0.3, 0.4), duration_s=0.4)
        w.step(0.2)
        half = gt.joint_offset("psm1")[2]
        w.step(0.3)
        dq = np.array([np.deg2rad(0.5), np.deg2rad(-0.3), 0.0004])
        np.testing.assert_allclose(gt.joint_offset("psm1")[:3], dq, atol=1e-12)
        assert 0.0001 < half < 0.0003  # ramped, not stepped
        w.psm1.servo_jp(m0)  # hold the measured value: the true joints move by the drift
        w.step(0.01)
        np.testing.assert_allclose(gt.joint_positions("psm1")[:3] - q0[:3], dq, atol=1e-12)
        np.testing.assert_allclose(w.psm1.measured_jp(), m0, atol=1e-12)
        with pytest.raises(ValueError, match="drift"):
            w.faults.drift("psm1", (0.6, 0, 0))


def _shake(w: World, seconds: float) -> None:
    """PSM2 (holding the needle) moves back and forth."""
    q0 = w.psm2.setpoint_jp()
    for k in range(int(seconds / 0.5)):
        w.psm2.move_jp(q0 + (0.1 if k % 2 == 0 else 0.0) * np.array([1, 0, 0, 1, 0, 0]))
        w.step(0.5)


RANDOM = {
    "servo": {"bandwidth_hz": [3, 12], "revolute_friction_deg": [0.5, 2.5]},
    "slip": {"rate_per_s": 0.5, "slide_mm": [0.1, 0.3]},
    "drift": {"rate_per_s": 0.5},
    "lighting": {"rate_per_s": 0.5},
}


def _events(seed: int) -> list:
    with held_world(seed=seed, faults=RANDOM) as w:
        _shake(w, 6.0)
        return GroundTruth(w).fault_events()


def test_scene_faults_are_seeded():
    a, b, c = _events(3), _events(3), _events(4)
    assert a == b and a != c
    kinds = {e.kind for e in a}
    assert {"servo_model", "slip", "drift", "lighting"} <= kinds
    plant = next(e for e in a if e.kind == "servo_model").params
    assert all(3 <= f <= 12 for f in plant["bandwidth_hz"]) and len(set(plant["bandwidth_hz"])) == 6


def test_profiles_and_validation():
    assert profile_names() == ("none", "mild", "harsh")
    mild = scene_from_dict({"faults": "mild"}).faults
    assert mild.servo.bandwidth_hz == (3.0, 12.0) and mild.slip.rate_per_s > 0
    over = scene_from_dict({"faults": {"profile": "mild", "drop": {"rate_per_s": 0}}}).faults
    assert over.drop.rate_per_s == 0 and over.slip == mild.slip


@pytest.mark.parametrize(
    "faults, message",
    [
        ("wild", "scene.faults: expected a profile (none, mild, harsh) or a mapping, got 'wild'"),
        ({"slip": {"rate_per_s": -1}}, "scene.faults.slip.rate_per_s: expected a non-negative"),
        ({"slip": {"speed": 1}}, "scene.faults.slip.speed: unknown key"),
        (
            {"servo": {"bandwidth_hz": [5, 2]}},
            "scene.faults.servo.bandwidth_hz: expected [low, high]",
        ),
        ({"servo": {"bandwidth_hz": [3, 80]}}, "scene.faults.servo.bandwidth_hz: expected [low"),
        (
            {"frame_lost": {"probability": 2}},
            "scene.faults.frame_lost.probability: expected a prob",
        ),
        ({"drift": {"max_deg": 1}}, "scene.faults.drift.max_deg: expected at most 0.5"),
        (
            {"schedule": [{"at": 1, "kind": "fire"}]},
            "scene.faults.schedule[0].kind: expected one of",
        ),
        ({"schedule": [{"kind": "drop"}]}, "scene.faults.schedule[0].at: missing"),
        ({"schedule": [{"at": 1, "kind": "drift"}]}, "scene.faults.schedule[0].arm: missing"),
        ({"schedule": [{"at": 1, "kind": "drift", "arm": "psm1", "dq": [0, 0, 0.7]}]}, "dq[2]"),
        ({"schedule": [{"at": 1, "kind": "dark", "frames": 0}]}, "schedule[0].frames: expected a"),
        ({"schedule": {"at": 1}}, "scene.faults.schedule: expected a list of faults"),
    ],
)
def test_bad_faults_give_one_line_naming_the_field(faults, message):
    with pytest.raises(SceneError) as info:
        scene_from_dict({"faults": faults})
    assert message in str(info.value) and "\n" not in str(info.value)


def test_scheduled_faults_from_the_scene_fire_at_their_time():
    faults = {
        "schedule": [
            {"at": 0.2, "kind": "slip", "angle_deg": 2, "slide_mm": 0.5},
            {"at": 0.4, "kind": "drop"},
        ]
    }
    with held_world(faults=faults) as w:
        gt = GroundTruth(w)
        w.step(0.3)
        assert [(e.kind, e.time, e.source) for e in gt.fault_events()] == [
            ("slip", 0.2, "schedule")
        ]
        w.step(0.2)
        assert gt.fault_events()[-1].kind == "drop" and gt.needle_holder() is None
