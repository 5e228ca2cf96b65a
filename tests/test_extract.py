"""The extraction's confirmation in a real single-throw session: one wrong presented answer is
refuted by a second view, and a check that must say no says no."""

import dataclasses

import numpy as np
import pytest
from recovery_helpers import finish, node, passed, running
from scipy.spatial.transform import Rotation

from suture_bt.runtime.session import RunOptions, Session
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.transforms import make_transform

EXTRACT = "Extract pair 1"


@pytest.fixture
def session():
    s = Session(RunOptions(tree="single_throw"))
    yield s
    s.close()


def turned_in_jaw(session, arm: str, deg: float):
    """A pose change that looks like a turn in ``arm``'s jaw: about the jaw's own axis through
    the held point (the wire stays between the blades and the plane across them, so the
    held-by and across-the-jaws tests pass it; a turn about the closing axis tilts the plane
    and the across-the-jaws test refuses it outright)."""
    T_tip = GroundTruth(session.world).tip_pose_world(arm)
    pivot = T_tip[:3, 3] - 0.0015 * T_tip[:3, 2]
    R = Rotation.from_rotvec(np.deg2rad(deg) * T_tip[:3, 2]).as_matrix()
    return make_transform(R, pivot - R @ pivot)


def wrong_answers(session, presented: list[float]):
    """Make the sensor's answers wrong: the look from the lift pose (checked against the
    gripper) turned 40°, the next presented ones each by the next of ``presented`` (degrees)."""
    sensor = session.context.sensor
    real = sensor.observe

    def observe(*args, **kwargs):
        obs = real(*args, **kwargs)
        if kwargs.get("prior_checked"):
            deg = 40.0
        elif presented:
            deg = presented.pop(0)
        else:
            return obs
        turn = turned_in_jaw(session, "psm1", deg)
        return dataclasses.replace(obs, T_world_needle=turn @ obs.T_world_needle)

    sensor.observe = observe
    return real


@pytest.mark.slow
def test_one_wrong_presented_answer_is_refuted_by_a_second_view(session):
    # A campaign trial's extraction ended its run on one confident wrong answer (47° off, its
    # wire between the blades). Here the look from the lift pose and the first presented look
    # answer 40° off; the next presentation (another pose) agrees with the gripper.
    assert session.run_until(running(session, EXTRACT, "pulling")) is not None
    real = wrong_answers(session, [40.0])
    try:
        throw = finish(session)
    finally:
        session.context.sensor.observe = real
    report = next(r for r in session.context.reports if r["behaviour"] == EXTRACT)
    assert report["status"] == "SUCCESS"
    assert report["second_look"] == {"agrees_with_gripper": True, "agrees_with_first": False}
    assert throw["status"] == "SUCCESS", throw["reason"]
    assert passed(session), session.scores()[0].failure


@pytest.mark.slow
def test_answers_off_the_gripper_that_disagree_with_each_other_fail_the_extraction(session):
    # Two presented answers off the gripper, each in another way: nothing confirms where the
    # needle is, and the extraction fails saying so.
    assert session.run_until(running(session, EXTRACT, "pulling")) is not None
    real = wrong_answers(session, [40.0, -35.0])
    try:
        session.run_until(lambda s: node(s, EXTRACT).status.name in ("SUCCESS", "FAILURE"))
    finally:
        session.context.sensor.observe = real
    report = next(r for r in session.context.reports if r["behaviour"] == EXTRACT)
    assert report["status"] == "FAILURE"
    assert report["second_look"] == {"agrees_with_gripper": False, "agrees_with_first": False}
    assert "agrees with neither" in report["checks"][-1]["detail"]
