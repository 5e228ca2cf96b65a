"""The suture task's own needle views for the needle-pose benchmark (issue 14, "Measure").

Each builder draws one scene (a :class:`~suture_bt.datagen.needle_data.SceneSample`: true arm
joints, needle pose) through the simulator's own kinematics and the skills' own geometry, plus
the task priors a caller would know there:

- ``held_start``: the SRC Task 3 start. PSM2 at the default initial joints, driven there with
  a hidden joint offset drawn within the task bound (5°, 5°, 5 mm on joints 1-3), the needle
  in its jaw at a grasp arc angle drawn in 57-180° (the world's own in-jaw hand); PSM1 at its
  own default pose with its own offset.
- ``held_presented``: a presentation pose the tree uses (``skills.presentation``: one of the
  first three candidates for the arm's view), either arm, the driving hand at a random arc
  angle or the pulling hand; the other arm at its default pose.
- ``in_port``: the needle partly inserted along the planned arc of a random pair
  (``suture_bt.planning.plan_needle_arc``), swept so that its tip has emerged at the exit
  (0.3 mm to the insertion's end), held by PSM2 at the insertion grasp
  (``skills.grasps.insertion_grasp_angle``), or by PSM1 at the pulling hand from the
  insertion's end until the base is 0.3 rad short of the exit (pulling through).
- ``handover``: the giver presents the needle on the taker's side (the presentation
  candidates toward the taker, as the handover skill asks); the taker's open jaw waits on
  the way to a grasp it reaches at another arc angle (at least the skills'
  ``MIN_JAW_SEPARATION`` away), 0-20 mm back (the skill's stand-by distance), in half the
  scenes moved out of the cameras' sight lines as the skill moves it
  (``skills.line_of_sight.clear_tip_pose``), in the other half not.

Priors (``task``): held by the holder at its pinch point from its joints, with the needle's
plane across its jaws (``AcrossJawsPrior``, the skills' calibrated tolerance); the arms in these
scenes are where their joints say once calibrated, so the tolerance is the calibrated 1 mm
(``held_start``: the joints the arm *reports*, i.e. commanded, would be off by the hidden
offset; the benchmark gives the calibrated pinch point, as the tree localises after
calibrating); in a port also the entry and exit ports (3 mm) and where along the needle the
jaw holds it (the grasp the tree made there, within the sensor's ``HELD_PLACE_TOL``; the
scene's jaw holds it off that place by a draw of ``HELD_PLACE_SPREAD``).

Since session 30 the points of those priors carry the errors measured where the tree gets
them (:func:`with_measured_errors`, drawn from their own random stream so the scenes stay the
same): a calibrated pinch point is off by the calibration's residual, and a port by how far
from it the tree's throws cross. Before, both were exact, which flattered the priors.
"""

from __future__ import annotations

from dataclasses import replace
from itertools import islice
from types import SimpleNamespace

import numpy as np

from suture_bt.datagen.needle_data import SceneSample
from suture_bt.kinematics import UnreachablePoseError, forward_kinematics, inverse_kinematics
from suture_bt.perception.in_hand import JAW_POINT_IN_TIP
from suture_bt.perception.needle_prior import AcrossJawsPrior, HeldPrior, PortPrior
from suture_bt.planning import plan_needle_arc, to_base
from suture_bt.skills import presentation
from suture_bt.skills.grasps import (
    END_MARGIN,
    MIN_JAW_SEPARATION,
    backed_off,
    hand,
    insertion_grasp_angle,
    pulling_grasp_angle,
    pulling_hand,
    tip_goal,
)
from suture_bt.skills.handover import STANDBY
from suture_bt.skills.held_priors import ACROSS_JAWS_DEG_CALIBRATED
from suture_bt.skills.line_of_sight import clear_tip_pose
from suture_bt.skills.needle_sensor import HELD_PLACE_TOL

TASK_SETS = ("held_start", "held_presented", "in_port", "handover")
#: Default initial joints of the SRC scene (sim/default_scene.yaml).
INITIAL_JP = {
    "psm1": np.array([0.4, -0.22, 0.139, 1.64, -0.37, 0.11]),
    "psm2": np.array([-0.4, -0.22, 0.139, -1.64, -0.37, -0.11]),
}
#: Task bound of the hidden joint offset (rad, rad, m).
OFFSET_BOUND = np.array([np.deg2rad(5.0), np.deg2rad(5.0), 0.005])
HELD_TOL = 0.001
PORT_TOL = 0.003
#: Spread (m, along the arc, normal) of where the jaw really holds the needle around where
#: the caller believes it does: the tree's belief after its grasps against the simulator's
#: grasp, 6 development campaign trials (seed 4242000, held-out phantom ranges; 48 grasps,
#: 111 beliefs): RMS 0.10 mm (PSM1's pulls) to 0.18 mm (PSM2's takes), largest 0.81 mm.
HELD_PLACE_SPREAD = 0.0002
JAW_CLOSED = 0.0
JAW_OPEN = 0.8
#: Error (m, per axis, normal) of a calibrated arm's pinch point: the calibration benchmark's
#: tip error after compensation (README, "Joint-offset calibration": 0.15 mm mean, 0.35 mm
#: p95 over 8 ports × 200 offsets); 0.12 mm per axis gives 0.19 mm mean, 0.34 mm p95.
PINCH_ERROR_STD = 0.00012
#: Error (m, per axis in the port's plane, normal) of where the wire crosses a port: the
#: lateral error of the tree's crossings in the held-out campaign of session 29
#: (docs/eval/heldout_s29_summary.md: entries 0.18 mm mean, 0.36 mm p95).
PORT_ERROR_STD = 0.00015


def with_measured_errors(priors: list, rng: np.random.Generator) -> list:
    """``priors`` with each held-by pinch point and port point moved by the error the tree's
    own would carry (PINCH_ERROR_STD in 3-D, PORT_ERROR_STD within the port's plane); the
    other priors as they are."""
    out = []
    for p in priors:
        if isinstance(p, HeldPrior):
            p = replace(
                p, pinch_point=np.asarray(p.pinch_point) + rng.normal(0, PINCH_ERROR_STD, 3)
            )
        elif isinstance(p, PortPrior):
            v = rng.normal(0.0, PORT_ERROR_STD, 3)
            if p.normal is not None:
                n = np.asarray(p.normal, float) / np.linalg.norm(p.normal)
                v -= n * (v @ n)
            p = replace(p, point=np.asarray(p.point) + v)
        out.append(p)
    return out


def _other(arm: str) -> str:
    return "psm1" if arm == "psm2" else "psm2"


def _with_offset(q: np.ndarray, rng) -> np.ndarray:
    q = np.array(q, float)
    q[:3] += rng.uniform(-OFFSET_BOUND, OFFSET_BOUND)
    return q


def _sample(scenario, T, q, jaw, rng) -> SceneSample:
    return SceneSample(
        scenario,
        T,
        q,
        jaw,
        brightness=float(rng.uniform(0.8, 1.6)),
        noise_std=float(rng.uniform(0.0, 4.0)),
    )


def _tip(sim, arm: str, q: np.ndarray) -> np.ndarray:
    return sim.sampler.bases[arm] @ forward_kinematics(q)


def _pinch(T_tip: np.ndarray) -> np.ndarray:
    return T_tip[:3, :3] @ JAW_POINT_IN_TIP + T_tip[:3, 3]


class _Arm:
    """The bits of an ArmHandle that ``skills.presentation`` reads (a calibrated arm)."""

    calibrated = True

    def __init__(self, name: str, base: np.ndarray, q: np.ndarray):
        self.name = name
        self._base = base
        self.servo = SimpleNamespace(setpoint_jp=lambda: q.copy(), estimated_jp=lambda: q.copy())

    def base_frame(self) -> np.ndarray:
        return self._base


def _held(sim, arm: str, q: np.ndarray, held_at: float | None = None) -> list:
    """The priors of a needle held by ``arm`` at joints ``q``: its pinch point (at arc angle
    ``held_at`` along the needle, when the caller's grasp knows it), and the plane across its
    jaws as every grasp of the task holds it."""
    T_tip = _tip(sim, arm, q)
    place = {} if held_at is None else {"arc_angle": held_at, "arc_tolerance": HELD_PLACE_TOL}
    return [
        HeldPrior(arm, _pinch(T_tip), HELD_TOL, **place),
        AcrossJawsPrior(arm, -T_tip[:3, 2], ACROSS_JAWS_DEG_CALIBRATED),
    ]


def _ctx(sim):
    return SimpleNamespace(
        camera=SimpleNamespace(model=sim.stereo),
        phantom=sim.world.task.phantom,
        needle=sim.model,
        belief=None,
    )


def _ik(sim, arm: str, T_world_tip: np.ndarray, q_now: np.ndarray) -> np.ndarray | None:
    try:
        return inverse_kinematics(to_base(T_world_tip, sim.sampler.bases[arm]), q_now)
    except UnreachablePoseError:
        return None


def _random_hand(sim, rng) -> np.ndarray:
    m = sim.model
    if rng.random() < 0.3:
        return pulling_hand(m)
    return hand(m, rng.uniform(m.tip_angle + END_MARGIN, m.base_angle - END_MARGIN))


def _presented(sim, rng, arm: str, T_hand: np.ndarray):
    """Joints presenting a needle held with ``T_hand`` (one of the first 3 candidates)."""
    cands = presentation.candidate_poses(
        _ctx(sim), _Arm(arm, sim.sampler.bases[arm], INITIAL_JP[arm])
    )[:3]
    if not cands:
        return None
    T_tip = cands[int(rng.integers(len(cands)))]
    q = _ik(sim, arm, T_tip, INITIAL_JP[arm])
    return None if q is None else (q, T_tip @ T_hand)


def held_start(sim, rng):
    a = np.deg2rad(rng.uniform(57.0, 180.0))
    q = {arm: _with_offset(INITIAL_JP[arm], rng) for arm in ("psm1", "psm2")}
    m = sim.model
    # The world's in-jaw hand (sim.world.World.in_jaw_grasp_pose) = the skills' driving hand.
    T = _tip(sim, "psm2", q["psm2"]) @ hand(m, a)
    jaw = {"psm1": 0.5, "psm2": JAW_CLOSED}
    priors = _held(sim, "psm2", q["psm2"])
    return _sample("held_start", T, q, jaw, rng), priors


def held_presented(sim, rng):
    for _ in range(50):
        arm = ("psm1", "psm2")[int(rng.integers(2))]
        got = _presented(sim, rng, arm, _random_hand(sim, rng))
        if got is None:
            continue
        q_arm, T = got
        q = {arm: q_arm, _other(arm): INITIAL_JP[_other(arm)].copy()}
        jaw = {arm: JAW_CLOSED, _other(arm): 0.5}
        priors = _held(sim, arm, q_arm)
        return _sample("held_presented", T, q, jaw, rng), priors
    raise RuntimeError("no reachable presentation in 50 draws")


def in_port(sim, rng):
    m = sim.model
    ph = sim.world.task.phantom
    for _ in range(100):
        pair = int(rng.integers(1, ph.num_pairs + 1))
        entry, exit_ = ph.pair(pair)
        arc = plan_needle_arc(entry, exit_, m)
        if rng.random() < 0.5:  # inserting: tip just out to the insertion's end
            arm, held_at, pulling = "psm2", insertion_grasp_angle(arc), False
            phi = rng.uniform(arc.port_angle + 0.0003 / m.radius, arc.insert_end_angle)
        else:  # pulling through: from the insertion's end until the base nears the exit
            arm, held_at, pulling = "psm1", pulling_grasp_angle(m), True
            phi = rng.uniform(arc.insert_end_angle, arc.base_at_exit_angle - 0.3)
        # The jaw holds the needle a little off where the grasp meant to (the caller's prior).
        T_hand = hand(m, held_at + rng.normal(0.0, HELD_PLACE_SPREAD) / m.radius, pulling)
        T = arc.needle_pose(phi)
        q_arm = _ik(sim, arm, tip_goal(T, T_hand), INITIAL_JP[arm])
        if q_arm is None:
            continue
        q = {arm: q_arm, _other(arm): INITIAL_JP[_other(arm)].copy()}
        jaw = {arm: JAW_CLOSED, _other(arm): 0.5}
        priors = _held(sim, arm, q_arm, held_at)
        for port in (entry, exit_):  # the ports the wire crosses (the prior's own test)
            prior = PortPrior(port.name, port.position, PORT_TOL, port.normal)
            if prior.miss(T, m) <= 1.0:
                priors.append(prior)
        return _sample("in_port", T, q, jaw, rng), priors
    raise RuntimeError("no reachable in-port grasp in 100 draws")


def handover(sim, rng):
    m = sim.model
    ctx = _ctx(sim)
    for _ in range(100):
        giver = ("psm1", "psm2")[int(rng.integers(2))]
        taker = _other(giver)
        # The giver presents on the taker's side, as the handover skill asks.
        cands = list(
            islice(
                presentation.iter_candidates(
                    ctx,
                    _Arm(giver, sim.sampler.bases[giver], INITIAL_JP[giver]),
                    toward=_Arm(taker, sim.sampler.bases[taker], INITIAL_JP[taker]),
                ),
                3,
            )
        )
        if not cands:
            continue
        T_tip = cands[int(rng.integers(len(cands)))]
        q_give = _ik(sim, giver, T_tip, INITIAL_JP[giver])
        if q_give is None:
            continue
        a_give = rng.uniform(m.tip_angle + END_MARGIN, m.base_angle - END_MARGIN)
        T = T_tip @ hand(m, a_give)
        angles = np.linspace(m.tip_angle + END_MARGIN, m.base_angle - END_MARGIN, 40)
        angles = angles[np.abs(angles - a_give) >= MIN_JAW_SEPARATION]
        rcm = sim.sampler.bases[taker][:3, 3]
        q_take = None
        for a_take in rng.permutation(angles):  # a grasp the taker reaches, at random
            goal = tip_goal(T, hand(m, float(a_take), pulling=bool(rng.integers(2))))
            if _ik(sim, taker, goal, INITIAL_JP[taker]) is None:
                continue
            wait = backed_off(goal, float(rng.uniform(0.0, STANDBY)))
            wait = clear_tip_pose(ctx, wait, rcm, T[:3, 3]) if rng.random() < 0.5 else wait
            q_take = _ik(sim, taker, wait, INITIAL_JP[taker]) if wait is not None else None
            if q_take is not None:
                break
        if q_take is None:
            continue
        q = {giver: q_give, taker: q_take}
        jaw = {giver: JAW_CLOSED, taker: JAW_OPEN}
        priors = _held(sim, giver, q_give)
        return _sample("handover", T, q, jaw, rng), priors
    raise RuntimeError("no reachable handover in 100 draws")


BUILDERS = {
    "held_start": held_start,
    "held_presented": held_presented,
    "in_port": in_port,
    "handover": handover,
}
