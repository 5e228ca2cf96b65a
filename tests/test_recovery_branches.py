"""Recovery branches in a real single-throw session: a fault forced through ``world.faults``,
then the tree's own record (recovery nodes' history, skill reports, the throw's reason)."""

import numpy as np
import pytest
from py_trees.common import Status

from suture_bt.behaviours.recovery import RecoveryNode
from suture_bt.runtime.session import RunOptions, Session
from suture_bt.sim.ground_truth import GroundTruth


@pytest.fixture
def session():
    s = Session(RunOptions(tree="single_throw"))
    yield s
    s.close()


def node(session, name: str):
    """The tree's node called ``name`` (the first, depth first)."""
    return next(n for n in session.root.iterate() if n.name == name)


def running(session, name: str, says: str = ""):
    """A stop predicate: node ``name`` runs and its feedback contains ``says``."""

    def hit(s) -> bool:
        n = node(s, name)
        return n.status == Status.RUNNING and says in (n.feedback_message or "")

    return hit


def finish(session) -> dict:
    session.run()
    assert session.error is None, session.error
    return session.context.throws[1]


def passed(session) -> bool:
    return bool(session.scores()[0].passed)


@pytest.mark.slow
def test_lost_frames_are_captured_again_in_calibration_and_localisation(session):
    session.world.faults.lose_frames(2, at=0.0)  # the first captures: PSM1's calibration
    assert session.run_until(running(session, "Localize needle in PSM2")) is not None
    session.world.faults.lose_frames(2)  # the next captures: the localisation's
    throw = finish(session)
    assert throw["status"] == "SUCCESS", throw["reason"]
    assert passed(session), session.scores()[0].failure
    cal = next(r for r in session.context.reports if r["behaviour"] == "Calibrate PSM1")
    assert len(cal["frames_lost"]) == 2 and cal["status"] == "SUCCESS"
    lost = [k for k, _ in session.context.sensor.bad_frames if k == "lost"]
    assert len(lost) == 2
    fired = [e for e in GroundTruth(session.world).fault_events() if e.kind == "frame_lost"]
    assert len(fired) == 4


@pytest.mark.slow
def test_unconfirmed_insertion_is_looked_at_again_and_confirmed(session):
    assert session.run_until(running(session, "Insert pair 1", "driving the needle")) is not None
    # Both confirmation looks lose all their frames: the emerged tip is not confirmed.
    session.world.faults.lose_frames(6)
    throw = finish(session)
    retry = node(session, "Retry: insert pair 1")
    ran = [(a, name, status) for a, name, status, _ in retry.history]
    assert ran == [
        (1, "Insert pair 1, PSM1 waits", Status.FAILURE),
        (1, "Recover insertion 1", Status.SUCCESS),
        (2, "Insert pair 1, PSM1 waits", Status.SUCCESS),
    ]
    assert "3 frames lost in a row" in retry.history[0][3]
    assert "succeeded on attempt 2 of 2" in retry.feedback_message
    reports = session.context.reports
    looked = [r for r in reports if r["behaviour"] == "Look at the tip past exit 1 again"]
    assert [r["status"] for r in looked] == ["SUCCESS"]
    # The needle stood at the end of its sweep: no back-out (it would re-enter at the exit).
    assert not any(r["skill"] == "back out" for r in reports)
    inserts = [r for r in reports if r["skill"] == "insert"]
    assert [bool(r.get("resumed")) for r in inserts] == [False, True, True]
    assert throw["status"] == "SUCCESS", throw["reason"]
    assert passed(session), session.scores()[0].failure


def ran(session, name: str) -> list[tuple[int, str, Status]]:
    """(attempt, child, status) of every child RecoveryNode ``name`` finished."""
    return [(a, child, status) for a, child, status, _ in node(session, name).history]


@pytest.mark.slow
def test_needle_dropped_before_the_insertion_is_picked_up_and_the_throw_resumed(session):
    assert session.run_until(running(session, "Insert pair 1", "approaching")) is not None
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


#: On the floor beyond the phantom's near edge: in the cameras' view, out of both arms' reach.
OUT_OF_REACH = (0.0, -0.12, 0.0421)


@pytest.mark.slow
def test_needle_dropped_out_of_both_arms_reach_fails_the_throw_saying_so(session, tmp_path):
    assert session.run_until(running(session, "Insert pair 1", "approaching")) is not None
    session.world.faults.drop("psm2")
    T = np.eye(4)
    T[:3, :3] = _rot_z(0.3)[:3, :3]
    T[:3, 3] = OUT_OF_REACH
    session.world.needle.set_pose(T)  # test API: the needle fell off the phantom
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
    assert not any(r["skill"] == "pick up" for r in session.context.reports[-3:])
    result = session.write(tmp_path)
    assert (tmp_path / "result.json").is_file()
    assert result["passed"] is False and result["tree_status"] == "FAILURE"
    assert "out of both arms' reach" in result["throws"][0]["tree_reason"]


@pytest.mark.parametrize("phi_deg", [0.0, 40.0, 90.0])
def test_back_out_finds_the_sweep_angle_of_a_needle_on_its_arc(phi_deg):
    from suture_bt.geometry import NeedleModel, PhantomModel
    from suture_bt.planning import plan_needle_arc
    from suture_bt.skills.recover import BackOut

    arc = plan_needle_arc(*PhantomModel().pair(1), NeedleModel())
    phi = min(np.deg2rad(phi_deg), arc.insert_end_angle)
    found, turn = BackOut._sweep_angle(arc, arc.needle_pose(phi))
    assert found == pytest.approx(phi, abs=np.deg2rad(1.0)) and turn < 1.0
    _, off = BackOut._sweep_angle(arc, arc.needle_pose(phi) @ _rot_x(np.deg2rad(20.0)))
    assert off > 15.0  # a needle off the arc's plane is refused (ON_ARC_DEG)


def _rot_z(a: float) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return T


def _rot_x(a: float) -> np.ndarray:
    T = np.eye(4)
    T[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return T
