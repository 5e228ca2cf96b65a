"""Can the arms do a throw from here? IK over the throw's planned poses, before moving.

For a port pair: the inserting arm, holding the needle at the grasp the pair needs, must reach
the approach poses above the entry and every sampled pose of the insertion sweep; the pulling
arm must reach the pulling grasp on the emerged needle and every sampled pose of the
extraction. The answer is '' or one line naming the pair, the port and the arm, so a phantom
placed out of reach ends the run before anything moves, with a reason a user can act on.
The arms' kinematics are used as they are (before calibration the hidden offset of a few
degrees moves the tip by millimetres; the per-pose skills check again as they go).
"""

from __future__ import annotations

import numpy as np

from suture_bt.planning import NeedleArcError, plan_needle_arc
from suture_bt.skills.context import TaskContext
from suture_bt.skills.grasps import hand, insertion_grasp_angle, pulling_hand, tip_goal
from suture_bt.skills.insert import LIFT, PRE_ARC
from suture_bt.skills.motion import feasible

#: Sweep poses checked per stage (the moves check every millimetre when they start).
SAMPLES = 9


def pair_reach(ctx: TaskContext, pair: int, inserter: str, puller: str) -> str:
    """'' when both arms can do the throw through ``pair``, else why not (one line)."""
    entry, exit_ = ctx.phantom.pair(pair)
    try:
        arc = plan_needle_arc(entry, exit_, ctx.needle)
    except NeedleArcError as e:
        return f"pair {pair}: {e.reason}"
    T_drive = hand(ctx.needle, insertion_grasp_angle(arc))
    inserting = [tip_goal(T, T_drive) for T in arc.approach_poses(PRE_ARC, LIFT)]
    phis = np.linspace(arc.pre_insertion_angle(PRE_ARC), arc.insert_end_angle, SAMPLES)
    inserting += [tip_goal(arc.needle_pose(p), T_drive) for p in phis]
    reason = feasible(ctx.arm(inserter), inserting)
    if reason:
        return f"pair {pair}: entry out of {inserter.upper()}'s reach at {entry.name} ({reason})"
    T_pull = pulling_hand(ctx.needle)
    phis = np.linspace(arc.insert_end_angle, arc.extract_end_angle, SAMPLES)
    reason = feasible(ctx.arm(puller), [tip_goal(arc.needle_pose(p), T_pull) for p in phis])
    if reason:
        return f"pair {pair}: exit out of {puller.upper()}'s reach at {exit_.name} ({reason})"
    return ""
