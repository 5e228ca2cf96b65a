"""Drop recoveries in a real single-throw session: a needle dropped before, during and after an
insertion, on its way to the tissue, out of reach, arched over the ridge or turned over, and
the geometry that tells where a dropped needle lies (caught in a port, hanging on its pair's
circle, part way through)."""

from dataclasses import replace
from math import inf
from types import SimpleNamespace

import numpy as np
import pytest
from py_trees.common import Status
from recovery_helpers import (
    CHECK_1,
    finish,
    node,
    passed,
    pose,
    ran,
    rot_x,
    rot_z,
    running,
    single_throw_session,
)

from suture_bt.behaviours.recovery import RecoveryNode
from suture_bt.runtime.session import RunOptions, Session
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.transforms import pose_to_transform

session = pytest.fixture(single_throw_session, name="session")


@pytest.mark.slow
def test_needle_dropped_before_the_insertion_is_picked_up_and_the_throw_resumed(session):
    # PSM2 brings the needle over entry 1 (the in-hand check before the insertion); the jaw
    # loses it 0.3 s into the move; it lands where physics puts it.
    assert session.run_until(running(session, CHECK_1, "bringing the needle")) is not None
    session.step(15)
    session.world.faults.drop("psm2")
    throw = finish(session)
    assert ran(session, "Retry: pair 1 after a drop") == [
        (1, "Pair 1 (time limit)", Status.FAILURE),
        (1, "Pick-up after a drop in pair 1 (time limit)", Status.SUCCESS),
        (2, "Pair 1 (time limit)", Status.SUCCESS),
    ]
    retry = node(session, "Retry: pair 1 after a drop")
    assert isinstance(retry, RecoveryNode) and retry.retries == 1
    assert "needle dropped by psm2" in retry.history[0][3]
    assert "succeeded on attempt 2 of 2" in retry.feedback_message
    reports = session.context.reports
    found = [r for r in reports if r["skill"] == "find dropped needle"]
    assert [(r["status"], r["dropped_by"]) for r in found] == [("SUCCESS", "psm2")]
    picked = [r for r in reports if r["behaviour"] == "PSM2 picks the dropped needle up"]
    assert [r["status"] for r in picked] == ["SUCCESS"]
    assert throw["status"] == "SUCCESS", throw["reason"]
    assert passed(session), session.scores()[0].failure
    assert GroundTruth(session.world).needle_holders() == ["psm1"]  # pulled through


@pytest.mark.slow
def test_needle_dropped_part_way_through_the_insertion_is_taken_again_and_driven_on(session):
    # 1.2 s into the sweep through pair 1 the jaw loses the needle: the tissue holds it, its
    # tip not yet out past the exit. It is seen where the gripper left it (a look checked
    # against that pose; before the localiser's floor came down to 20 mm it was refused and
    # the frame was read along the circle instead, tip_reading.read_hanging).
    assert session.run_until(running(session, "Insert pair 1", "driving the needle"))
    session.step(60)
    session.world.faults.drop("psm2")
    assert GroundTruth(session.world).needle_holders() == []
    throw = finish(session)
    reports = session.context.reports
    found = next(r for r in reports if r["skill"] == "find dropped needle")
    assert found["status"] == "SUCCESS" and found["driven_in_pair"] == 1
    assert found["where_it_was"].startswith(("seen", "hanging there: read"))
    done = [(r["behaviour"], r["status"]) for r in reports if r["t_start"] >= found["t_start"]]
    assert done[:4] == [
        ("Find the dropped needle", "SUCCESS"),
        ("PSM2 takes the needle hanging in pair 1", "SUCCESS"),
        ("Drive the dropped needle on through pair 1", "SUCCESS"),
        ("Pull the re-driven needle through pair 1", "SUCCESS"),
    ]
    driven = next(r for r in reports if r["behaviour"].startswith("Drive the dropped"))
    assert 0.0 < driven["resumed_from_deg"] < driven["arc"]["insert_end_angle_deg"]
    assert node(session, "Unless pair 1 is pulled through").feedback_message.startswith(
        "skipped: pair 1 pulled through"
    )
    assert throw["status"] == "SUCCESS", throw["reason"]
    assert passed(session), session.scores()[0].failure


@pytest.mark.slow
def test_needle_dropped_on_its_way_to_the_tissue_is_found_and_picked_up(session):
    # PSM2 (uncalibrated) carries the start needle to where it would lay it down; before any
    # estimate names a holder the jaw loses it (the watch knows the holder from the start's
    # jaw reading). The needle is found on the tissue, PSM2 calibrates with its now empty jaw
    # and picks it up at the throw's grasp; the retried preparation then finds both arms
    # ready and skips the rest.
    lay = node(session, "PSM2 lays the needle on the tissue")
    assert session.run_until(lambda s: lay.status == Status.RUNNING) is not None
    session.step(10)
    session.world.faults.drop("psm2")
    throw = finish(session)
    assert ran(session, "Retry: prepare after a drop") == [
        (1, "Unless both arms are ready", Status.FAILURE),
        (1, "Pick-up after a drop in preparation (time limit)", Status.SUCCESS),
        (2, "Unless both arms are ready", Status.SUCCESS),
    ]
    retry = node(session, "Retry: prepare after a drop")
    assert "needle dropped by psm2" in retry.history[0][3]
    assert node(session, "Unless both arms are ready").feedback_message.startswith(
        "skipped: psm1, psm2 calibrated and psm2 already holds the needle"
    )
    done = [(r["behaviour"], r["status"]) for r in session.context.reports]
    assert done[:4] == [
        ("Calibrate PSM1", "SUCCESS"),
        ("Find the dropped needle", "SUCCESS"),
        ("Calibrate PSM2 (needle dropped)", "SUCCESS"),
        ("PSM2 picks the dropped needle up (preparation)", "SUCCESS"),
    ]
    assert throw["status"] == "SUCCESS", throw["reason"]
    assert passed(session), session.scores()[0].failure


#: On the floor beyond the phantom's near edge: in the cameras' view, out of both arms' reach.
OUT_OF_REACH = (0.0, -0.12, 0.0421)


@pytest.mark.slow
def test_needle_dropped_out_of_both_arms_reach_fails_the_throw_saying_so(session, tmp_path):
    # PSM2 brings the needle over entry 1 (the in-hand check before the insertion).
    assert session.run_until(running(session, CHECK_1, "bringing the needle")) is not None
    session.world.faults.drop("psm2")
    session.world.needle.set_pose(pose(rot_z(0.3), OUT_OF_REACH))  # test API: off the phantom
    # About 250 mm from the cameras, beyond the localiser's working range: its predicted
    # position spread (about 0.7 mm) is refused by the 0.6 mm gate ("not found"). Loosened
    # here, so that the needle is localised and the out-of-reach path is what is tested. So is
    # the exposure gate: the fitted arc runs 11 mm over the dark floor where the mask holds no
    # wire, and since the tree's localiser knows the phantom (session 18) the floor cannot hide
    # it ("not found" again). And so is the spread limit, which without priors is 1.5° since
    # session 19: this far away the fit's predicted angle spread is 1.9°.
    localizer = session.context.sensor.localizer
    localizer.gates = replace(
        localizer.gates, max_position_std_mm=inf, max_exposed=inf, max_angle_std_deg=inf
    )
    t_drop = session.context.clock.now()
    throw = finish(session)
    assert throw["status"] == "FAILURE"
    assert "needle dropped by psm2 and out of both arms' reach: psm2: " in throw["reason"]
    assert "; psm1: " in throw["reason"]
    assert session.context.clock.now() - t_drop < 10.0  # no hang: it fails as soon as it knows
    assert session.root.status == Status.FAILURE
    retry = node(session, "Retry: pair 1 after a drop")
    assert [h[1:3] for h in retry.history] == [
        ("Pair 1 (time limit)", Status.FAILURE),
        ("Pick-up after a drop in pair 1 (time limit)", Status.FAILURE),
    ]
    after = [r for r in session.context.reports if r["t_start"] >= t_drop]
    assert not any(r["skill"] == "pick up" for r in after)
    result = session.write(tmp_path)
    assert (tmp_path / "result.json").is_file()
    assert result["passed"] is False and result["tree_status"] == "FAILURE"
    assert "out of both arms' reach" in result["throws"][0]["tree_reason"]


#: A mild campaign trial's needle, dropped on its way to entry 3, came to rest upright and
#: arched over the ridge (tip on the tissue before the entry, base on the exit flank); here the
#: same pose in the phantom frame, moved along the ridge to pair 1.
ARCH_AT_PAIR_1 = np.array(
    [[-0.72156, -0.69234, -0.00428, -0.00344], [-0.00743, 0.00157, 0.99997, 0.0439],
     [-0.69231, 0.72157, -0.00628, 0.06936], [0.0, 0.0, 0.0, 1.0]]
)  # fmt: skip


@pytest.mark.slow
def test_needle_dropped_arched_over_the_ridge_is_picked_up_from_the_side(session):
    assert session.run_until(running(session, CHECK_1, "bringing the needle")) is not None
    session.world.faults.drop("psm2")
    u, _, vt = np.linalg.svd(ARCH_AT_PAIR_1[:3, :3])
    arch = ARCH_AT_PAIR_1.copy()
    arch[:3, :3] = u @ vt  # the printed rotation, made orthonormal again
    session.world.needle.set_pose(arch)  # test API: where the dropped needle lands
    throw = finish(session)
    reports = session.context.reports
    found = [r for r in reports if r["skill"] == "find dropped needle"]
    assert [r["status"] for r in found] == ["SUCCESS"], found[0].get("failure")
    picked = [r for r in reports if r["behaviour"] == "PSM2 picks the dropped needle up"]
    assert [r["status"] for r in picked] == ["SUCCESS"]
    assert picked[0]["hand"].endswith("from the side") and picked[0]["needle_tilt_deg"] > 60.0
    assert throw["status"] == "SUCCESS", throw["reason"]
    assert passed(session), session.scores()[0].failure


#: Where the needle dropped while approaching entry 1 came to rest (flat, z up): in view and
#: in PSM2's reach.
ON_TISSUE = (-0.0172, 0.0052, 0.0717)


@pytest.mark.slow
def test_needle_dropped_in_the_hand_back_lands_turned_over_is_picked_up_and_re_taken():
    from suture_bt.behaviours.actions import grasp_for_pairs

    session = Session(RunOptions(tree="multi_throw"))
    try:
        hand_back = node(session, "Hand back after pair 1")
        assert session.run_until(lambda s: hand_back.status == Status.RUNNING) is not None
        session.world.faults.drop("psm1")
        # Where it lands, turned over (test API). Physics alone landed it turned over until
        # session 16; with the calibration's reprojection refinement the drop lands it face up.
        turned_over = pose_to_transform(ON_TISSUE, (np.pi, 0.0, 0.0))
        session.world.needle.set_pose(turned_over)
        re_take = node(session, "Re-grasp for pair 2 to re-take it: PSM2 → PSM1 → PSM2")
        assert session.run_until(lambda s: re_take.status == Status.SUCCESS) is not None
        assert session.context.throws[1]["status"] == "SUCCESS"
        assert ran(session, "Retry: pair 1 after a drop") == [
            (1, "Pair 1 (time limit)", Status.FAILURE),
            (1, "Pick-up after a drop in pair 1 (time limit)", Status.SUCCESS),
            (2, "Pair 1 (time limit)", Status.SUCCESS),
        ]
        assert "needle dropped by psm1" in node(session, "Retry: pair 1 after a drop").history[0][3]
        skipped = node(session, "Unless pair 1 is pulled through").feedback_message
        assert skipped.startswith("skipped: pair 1 pulled through at t = ")
        assert node(session, "Unless PSM2 already holds it").feedback_message.startswith(
            "skipped: psm2 already holds the needle"
        )
        reports = session.context.reports
        assert [r["status"] for r in reports if r["behaviour"] == "Insert pair 1"] == ["SUCCESS"]
        pick = next(r for r in reports if r["behaviour"] == "PSM2 picks the dropped needle up")
        later = np.rad2deg(grasp_for_pairs((2, 3, 4))(session.context))
        assert pick["status"] == "SUCCESS" and pick["arc_angle_deg"] == pytest.approx(later)
        assert pick["hand"] == "turned over"  # the only hand from above; throw 2 re-takes it
        assert passed(session), session.scores()[0].failure
    finally:
        session.close()


def test_a_needle_turned_over_is_taken_from_above_and_one_on_its_edge_from_the_side():
    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.geometry.tissue_surface import height_above_tissue
    from suture_bt.skills.base import SkillFailure
    from suture_bt.skills.dropped import pick_up_paths
    from suture_bt.skills.resting_grasp import SIDE_CLEARANCE, resting_grasps

    ctx = SimpleNamespace(phantom=PhantomModel(), needle=NeedleModel())
    flat = pose(np.eye(4), ON_TISSUE)
    # straight down first, then the same hand with its jaws turned about the wire
    paths = pick_up_paths(ctx, flat, 2.8)
    assert len(paths) > 1 and all(len(p) == 3 for p in paths)
    [(hover, grasp, lift), *_] = pick_up_paths(ctx, flat @ rot_x(np.pi), 2.8)  # turned over
    down = -PhantomModel().T_world_phantom[:3, 2]
    assert grasp[:3, 2] @ down > np.cos(np.deg2rad(1.0))  # jaws straight down, as for flat
    assert np.linalg.norm(grasp[:3, 3] - hover[:3, 3]) > 0.005
    # Seen in a mild campaign trial: dropped on the way to entry 3, it came to rest upright,
    # arched over the ridge (tip on the tissue before the entry, base on the exit flank).
    arch = np.array(
        [[-0.7319, -0.6814, 0.0053, -0.0012], [0.0032, 0.0044, 1.0, 0.0],
         [-0.6815, 0.7319, -0.001, 0.0691], [0.0, 0.0, 0.0, 1.0]]
    )  # fmt: skip
    arch[:3, :3] = np.linalg.svd(arch[:3, :3])[0] @ np.linalg.svd(arch[:3, :3])[2]
    grasps = resting_grasps(ctx, arch, 2.6)
    assert {g.hand for g in grasps} == {"driving, from the side", "turned over, from the side"}
    for g in grasps:
        jaw = (arch @ np.linalg.inv(g.T_tip_needle))[:3, :3]
        assert abs(jaw[:, 2] @ down) < np.sin(np.deg2rad(10.0))  # jaws come in level
        wire = arch @ np.r_[ctx.needle.point_at(g.arc_angle), 1.0]
        assert height_above_tissue(ctx.phantom, wire[None, :3])[0] >= SIDE_CLEARANCE
    with pytest.raises(SkillFailure, match="no side grasp clear of the tissue"):
        sunk = arch.copy()
        sunk[:3, 3] -= 0.006 * PhantomModel().T_world_phantom[:3, 2]  # sunk into the ridge
        pick_up_paths(ctx, sunk, 2.6)


def test_a_needle_in_a_port_is_caught_and_one_on_the_tissue_beyond_the_ridge_is_not():
    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.planning import plan_needle_arc
    from suture_bt.skills.dropped import caught_in_tissue

    phantom = PhantomModel()
    ctx = SimpleNamespace(phantom=phantom, needle=NeedleModel())
    arc = plan_needle_arc(*phantom.pair(2), NeedleModel())
    assert caught_in_tissue(ctx, arc.needle_pose(np.deg2rad(30.0))).startswith("hanging in entry2")
    # Seen in a run: dropped in the hand-back, lying turned over on the exit side of the ridge
    # level with pair 2 (entry 2's axis, continued through the ridge, passes under it).
    beyond = pose(rot_x(np.pi), (0.0174, 0.0224, 0.0712))
    assert caught_in_tissue(ctx, beyond) == ""
    # Arched over the ridge near entry 3 (below entry 3's flank plane near the crest, but
    # above the exit flank there: outside the ridge) is lying on it, not caught.
    arch = np.array(
        [[-0.7319, -0.6814, 0.0053, -0.0012], [0.0032, 0.0044, 1.0, 0.0],
         [-0.6815, 0.7319, -0.001, 0.0691], [0.0, 0.0, 0.0, 1.0]]
    )  # fmt: skip
    assert caught_in_tissue(ctx, arch) == ""


def test_a_needle_hanging_on_its_pairs_circle_with_the_tip_out_can_be_taken_again():
    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.planning import plan_needle_arc
    from suture_bt.skills.context import TaskContext
    from suture_bt.skills.dropped import hanging_in_pair

    phantom, needle = PhantomModel(), NeedleModel()
    ctx = SimpleNamespace(phantom=phantom, needle=needle)
    ctx.plan = lambda pair, where: TaskContext.plan(ctx, pair, where)
    arc = plan_needle_arc(*phantom.pair(3), needle)
    pulled = arc.needle_pose(arc.insert_end_angle + 0.2)  # dropped while being pulled
    assert hanging_in_pair(ctx, pulled, 3) == ""
    assert hanging_in_pair(ctx, pulled, 2).startswith("not on pair 2's circle")
    slid = pulled.copy()
    slid[2, 3] -= 0.010  # slid 10 mm down the channel
    assert hanging_in_pair(ctx, slid, 3).startswith("not on pair 3's circle")
    early = arc.needle_pose(0.3)  # tip barely in: nothing out past the exit to take
    assert "out past exit 3" in hanging_in_pair(ctx, early, 3)


def test_a_needle_dropped_part_way_through_its_pair_can_be_driven_on():
    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.planning import plan_needle_arc
    from suture_bt.skills.context import TaskContext
    from suture_bt.skills.dropped import driven_in_pair

    phantom, needle = PhantomModel(), NeedleModel()
    ctx = SimpleNamespace(phantom=phantom, needle=needle)
    ctx.plan = lambda pair, where: TaskContext.plan(ctx, pair, where)
    arc = plan_needle_arc(*phantom.pair(3), needle)
    assert driven_in_pair(ctx, arc.needle_pose(0.3), 3) == ""  # tip in the ridge
    assert driven_in_pair(ctx, arc.needle_pose(0.3), 1).startswith("not on pair 1's circle")
    assert "not yet in entry 3" in driven_in_pair(ctx, arc.needle_pose(-0.2), 3)
    pulled = arc.needle_pose(arc.insert_end_angle + 0.2)
    assert "far enough for the puller" in driven_in_pair(ctx, pulled, 3)
