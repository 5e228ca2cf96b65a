"""Motion stack in the real World: PI servo + offset compensation + Cartesian moves to the ports,
planned needle insertions scored by the phantom's crossing records (issue 3, "Done when"), and
the other arm pulling the needle through along the planned extraction.

Ground truth is used here only to set Δq̂ to the true offset and to read the true tip/needle.
"""

import numpy as np
import pytest

from suture_bt.control import PIServo
from suture_bt.planning import (
    CartesianMove,
    MoveStatus,
    PoseSequenceMove,
    gripper_poses,
    in_base,
    plan_needle_arc,
    to_base,
)
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World
from suture_bt.transforms import make_transform

#: PSM2 (at −x) serves the entries, PSM1 (at +x) the exits.
ARM_FOR_KIND = {"entry": "psm2", "exit": "psm1"}


def drive(world, moves, settle: float, limit: float = 20.0) -> dict[str, MoveStatus]:
    """Hand started moves to their PI servos, step the world in 50 ms ticks until all end,
    then hold for ``settle`` s (the servos advance the moves at their own rate)."""
    for m in moves.values():
        m.sink.follow(m)
    t = 0.0
    while t < limit and not all(m.status.done or m.status.failed for m in moves.values()):
        world.step(0.05)
        t += 0.05
    world.step(settle)
    return {name: m.status for name, m in moves.items()}


@pytest.mark.parametrize("condition", ["B", "C"])
def test_true_tip_reaches_every_port_with_the_true_offset_estimate(condition):
    scene = scene_from_dict(
        {
            "servo": {"error_model": True},
            "arms": {"psm1": {"joint_offset": condition}, "psm2": {"joint_offset": condition}},
        }
    )
    with World.from_scene(scene, with_camera=False) as world:
        truth = GroundTruth(world)
        servos = {}
        for name in ("psm1", "psm2"):
            dq = truth.joint_offset(name)[:3]
            assert np.linalg.norm(dq) > 1e-3  # the condition is really applied
            servos[name] = PIServo(world.arms[name], offset_estimate=dq)
            servos[name].reset()
            servos[name].attach(world.add_periodic)
        errors = []
        phantom = world.task.phantom
        for pair in range(1, phantom.num_pairs + 1):
            ports = dict(zip(("psm2", "psm1"), phantom.pair(pair), strict=True))
            moves = {}
            for name, port in ports.items():
                goal = to_base(port.tip_pose_into_tissue(), world.arms[name].base_frame())
                moves[name] = CartesianMove(servos[name], goal, v_lin=0.05, a_lin=0.4)
                st = moves[name].start()
                assert not st.failed, st.reason
            status = drive(world, moves, settle=0.4)
            assert all(s.done for s in status.values())
            for name, port in ports.items():
                tip = truth.tip_pose_world(name)
                errors.append(np.linalg.norm(tip[:3, 3] - port.position))
        print(condition, np.round(np.array(errors) * 1e3, 3))
        assert max(errors) < 0.3e-3, np.round(np.array(errors) * 1e3, 3)


# ---------------------------------------------------------------- needle insertion
MOVED_PHANTOM = {"position": [0.03, -0.02, 0.0], "rpy": [0.0, 0.0, float(np.deg2rad(15.0))]}
GRASP_ARC_DEG = 155.0
#: Tip starts this far (arc length) before the entry, and the approach comes down to it along
#: the entry normal from this height.
PRE_ARC, LIFT = 0.006, 0.010
#: Needle sweep speed limits (rad/s, rad/s²): the tip moves at up to 6 mm/s.
SWEEP = {"angular_speed": 0.6, "angular_acc": 2.4}


def phantom_recorder(world):
    """The world's phantom bookkeeping: port crossings, tip out past exits, tissue strain."""
    assert world.phantom is not None
    return world.phantom


def throw_passes(recorder, pair: int) -> tuple[bool, str]:
    """SRC throw rule (DESIGN.md §5) on the recorded crossings of one pair, plus strain."""
    xs = [c for c in recorder.crossings if c.pair == pair]
    entry = [c for c in xs if c.kind == "entry" and c.src_direction]
    exit_ = [c for c in xs if c.kind == "exit" and c.src_direction]
    if not entry or not exit_:
        return False, f"crossings: {[(c.port, c.inward) for c in recorder.crossings]}"
    e, x = entry[0], exit_[0]
    strain = max((s.circle for s in recorder.max_strain.values()), default=0.0)
    msg = (
        f"entry lateral {e.lateral * 1e3:.2f} mm, exit lateral {x.lateral * 1e3:.2f} mm, "
        f"tip out {x.tip_out * 1e3:.2f} mm, strain {strain * 1e3:.3f} mm"
    )
    ok = (
        e.t < x.t
        and e.lateral <= 2.5e-3
        and x.lateral <= 2.5e-3
        and x.tip_out >= 5e-3
        and strain <= 0.5e-3
    )
    return ok, msg


def start_servo(world, arm: str) -> PIServo:
    """A PI servo (zero offset estimate) holding the arm where it is, run by the world."""
    servo = PIServo(world.arms[arm])
    servo.reset()
    servo.attach(world.add_periodic)
    return servo


def insertion_world(phantom: str) -> World:
    """Task-3 start: PSM2 holds the needle; servo error model on, zero offsets."""
    overrides = {
        "servo": {"error_model": True},
        "needle": {"start": "in_psm2_jaw", "grasp_arc_angle_deg": GRASP_ARC_DEG},
    }
    if phantom == "moved":
        overrides["phantom"] = MOVED_PHANTOM
    return World.from_scene(scene_from_dict(overrides), with_camera=False)


def insert(world, servo: PIServo, pair: int):
    """Approach and run the planned insertion with PSM2; returns the arc."""
    truth = GroundTruth(world)
    # The true needle-in-gripper transform (ground truth, test only).
    T_gn = np.linalg.inv(truth.tip_pose_world("psm2")) @ truth.needle_pose()
    entry, exit_ = world.task.phantom.pair(pair)
    arc = plan_needle_arc(entry, exit_, world.task.needle)
    arc.check_grasp(T_gn)
    base = world.psm2.base_frame()
    phi0 = arc.pre_insertion_angle(PRE_ARC)
    goals = [to_base(T @ np.linalg.inv(T_gn), base) for T in arc.approach_poses(PRE_ARC, LIFT)]
    approach = CartesianMove(servo, goals, v_lin=0.08, a_lin=0.4, v_ang=1.2, a_ang=4.0)
    st = approach.start()
    assert not st.failed, st.reason
    assert drive(world, {"psm2": approach}, settle=0.3)["psm2"].done
    insertion = in_base(gripper_poses(arc.insertion(start_angle=phi0, **SWEEP), T_gn), base)
    move = PoseSequenceMove(servo, insertion.times, insertion.poses)
    st = move.start()
    assert not st.failed, st.reason
    assert drive(world, {"psm2": move}, settle=0.2)["psm2"].done
    return arc


@pytest.mark.parametrize("phantom", ["default", "moved"])
@pytest.mark.parametrize("pair", [1, 2, 3, 4])
def test_planned_insertion_passes_the_src_throw_rule(phantom, pair):
    with insertion_world(phantom) as world:
        recorder = phantom_recorder(world)
        insert(world, start_servo(world, "psm2"), pair)
        ok, msg = throw_passes(recorder, pair)
        print(phantom, pair, msg)
        assert ok, msg


def extraction_hand(needle, arc_angle: float) -> np.ndarray:
    """PSM1's grasp (needle in its tip frame) at an arc angle: jaws across the needle plane."""
    t = np.array([np.sin(arc_angle), -np.cos(arc_angle), 0.0])
    r = np.array([np.cos(arc_angle), np.sin(arc_angle), 0.0])
    R = np.stack([t, -r, [0.0, 0.0, -1.0]])  # rows: tip axes in the needle frame
    return make_transform(R, np.array([0.0, 0.0, -0.0015]) - R @ needle.point_at(arc_angle))


def test_other_arm_pulls_the_needle_through_along_the_planned_extraction():
    with insertion_world("default") as world:
        truth = GroundTruth(world)
        recorder = phantom_recorder(world)
        arc = insert(world, start_servo(world, "psm2"), 2)
        servo1 = start_servo(world, "psm1")
        # PSM1 takes the part of the needle out past the exit, 15° behind the tip.
        needle = world.task.needle
        hand = extraction_hand(needle, needle.tip_angle + np.deg2rad(15.0))
        T_grip = arc.needle_pose(arc.insert_end_angle) @ np.linalg.inv(hand)
        T_back = T_grip.copy()
        T_back[:3, 3] -= 0.01 * T_grip[:3, 2]  # come in along the jaws
        base1 = world.psm1.base_frame()
        world.psm1.jaw.open()
        reach = CartesianMove(servo1, [to_base(T_back, base1), to_base(T_grip, base1)], v_lin=0.08)
        st = reach.start()
        assert not st.failed, st.reason
        assert drive(world, {"psm1": reach}, settle=0.3)["psm1"].done
        world.psm1.jaw.close()
        world.step(0.6)
        assert truth.needle_holders() == ["psm2", "psm1"], world.last_grasp["psm1"].reason
        world.psm2.jaw.open()
        world.step(0.3)
        assert truth.needle_holders() == ["psm1"]
        T_gn1 = np.linalg.inv(truth.tip_pose_world("psm1")) @ truth.needle_pose()
        n_crossings = len(recorder.crossings)
        ext = in_base(gripper_poses(arc.extraction(**SWEEP), T_gn1), base1)
        move = PoseSequenceMove(servo1, ext.times, ext.poses)
        st = move.start()
        assert not st.failed, st.reason
        assert drive(world, {"psm1": move}, settle=0.2)["psm1"].done
        # The needle has left the tissue, and never strained it by more than 0.5 mm.
        assert not recorder.inserted(truth.needle_pose())
        assert len(recorder.crossings) == n_crossings  # the tip stayed out
        strain = max(s.circle for s in recorder.max_strain.values())
        print(f"extraction: max strain {strain * 1e3:.3f} mm")
        assert strain <= 0.5e-3
