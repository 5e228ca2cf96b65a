"""The task priors of a needle held by an arm, as the needle sensor takes them.

A look at a held needle passes the localiser what the grasp says (``VisionNeedleSensor.observe``
keywords): the wire passes between the holder's jaws at its pinch point (within a tolerance
that depends on whether the arm is calibrated), with the needle's plane across the jaws the way
the grasp holds it (:mod:`localize_needle`'s looks; the limits are also its checks of an
answer against the grasp).
"""

from __future__ import annotations

import numpy as np

from suture_bt.perception.in_hand import BLADE_Z_RANGE, JAW_POINT_IN_TIP
from suture_bt.skills.context import TaskContext
from suture_bt.skills.tip_uncertainty import worst_offset_displacement

#: A held needle's wire must pass this close to the holder's blades (m; anywhere along the
#: stretch that holds it, ``in_hand.BLADE_Z_RANGE``) once the arm is calibrated; before, the
#: margin adds the tip displacement of the largest hidden joint
#: offset the task allows (SRC: 5°, 5°, 5 mm) at the arm's present joints.
HOLD_TOLERANCE_CALIBRATED = 0.002
HOLD_MARGIN_UNCALIBRATED = 0.004
#: The localiser's held-by prior measures from the pinch point (``JAW_POINT_IN_TIP``); the
#: wire may sit anywhere along the blades (``BLADE_Z_RANGE``), up to this much deeper (m).
PINCH_TO_BLADE_END = float(JAW_POINT_IN_TIP[2] - BLADE_Z_RANGE[0])

#: A needle driver holds the needle with its jaws across the needle plane (every grasp of the
#: task: the plane's normal along the tip's z axis; needle z against it, but for a needle
#: picked up turned over, whose belief says so); an uncalibrated arm's tip is turned by
#: up to ~7° by its hidden offset and a slip tilts the needle by up to 10° (harsh profile).
#: The localiser's confident twins at the Task 3 start had their plane 39-45° off (dev trial
#: 8130007): they passed the loose held-by test of an uncalibrated arm, not this one (deg).
ACROSS_JAWS_DEG = 20.0
#: The same for a calibrated holder: its tip is where its joints say, but slips may have
#: tilted the needle in the jaw (harsh profile: up to 10° each). Either limit also goes to the
#: localiser as a prior (:class:`~suture_bt.perception.needle_prior.AcrossJawsPrior`): its
#: signed test refuses a mirror twin (136-163° off at the Task 3 start's presentations), and it
#: tells base from tip when the swage band does not show.
ACROSS_JAWS_DEG_CALIBRATED = 30.0


def hold_tolerance(arm) -> float:
    """How far (m) the wire may pass from ``arm``'s pinch point as its joints give it."""
    if arm.calibrated:
        return HOLD_TOLERANCE_CALIBRATED
    return HOLD_MARGIN_UNCALIBRATED + worst_offset_displacement(arm.servo.estimated_jp())


def held_face(ctx: TaskContext, holder: str, T_world_tip: np.ndarray) -> np.ndarray:
    """The needle's z axis (world) as ``holder``'s grasp holds it: the believed in-hand pose's,
    else against the tip's z axis (the hand of the Task 3 start, of a handover and of a pick-up
    from a needle lying face up; only a needle picked up turned over is held the other way, and
    its belief says so)."""
    b = ctx.belief
    if b is not None and b.holder == holder and b.T_tip_needle is not None:
        return T_world_tip[:3, :3] @ np.asarray(b.T_tip_needle)[:3, 2]
    return -T_world_tip[:3, 2]


def held_priors(ctx: TaskContext, holder: str) -> dict:
    """``observe`` keywords for a needle held by ``holder``: its measured tip pose, the pinch
    tolerance (to the blades' far end), and the across-the-jaws face and limit."""
    arm = ctx.arm(holder)
    tip = arm.tip_world()
    return {
        "holder": (arm.name, tip),
        "holder_tolerance": hold_tolerance(arm) + PINCH_TO_BLADE_END,
        "jaw_tolerance_deg": ACROSS_JAWS_DEG_CALIBRATED if arm.calibrated else ACROSS_JAWS_DEG,
        "held_face": held_face(ctx, holder, tip),
    }
