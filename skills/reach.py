"""Can the arms do a throw from here? IK over the throw's planned poses, before moving.

For a port pair: the inserting arm, holding the needle at the grasp the pair needs, must reach
the approach poses above the entry and every sampled pose of the insertion sweep; the pulling
arm must reach the pulling grasp on the emerged needle and every sampled pose of the
extraction. The answer is '' or one line naming the pair, the port and the arm, so a phantom
placed out of reach ends the run before anything moves, with a reason a user can act on. The
arms' kinematics are used as they are (before calibration the hidden offset of a few degrees
moves the tip by millimetres; the per-pose skills check again as they go). The exit must also
be in both cameras' view: the emerged tip is confirmed from images, and an insertion whose exit
no camera sees could only be backed out of (through its exit: a stab), so such a pair is
refused before anything moves.
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
#: Pixels the exit port keeps from the image border.
VIEW_MARGIN_PX = 20


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
    return exit_out_of_view(ctx, pair, exit_)


def exit_out_of_view(ctx: TaskContext, pair: int, exit_) -> str:
    """'' when the exit port projects inside both images (``VIEW_MARGIN_PX`` to spare), else
    which image it leaves. (The tip, driven on far past the exit, may leave the image: the
    confirmation reads the emerged piece next to the exit.)"""
    p = np.asarray(exit_.position, dtype=float)
    for eye, cam in (("left", ctx.camera.model.left), ("right", ctx.camera.model.right)):
        u, v = cam.project(p[None])[0]
        m = VIEW_MARGIN_PX
        if not (m <= u <= cam.width - m and m <= v <= cam.height - m):
            return (
                f"pair {pair}: {exit_.name} out of the {eye} camera's view (pixel {u:.0f}, "
                f"{v:.0f} of {cam.width}×{cam.height}): the emerged tip could not be confirmed"
            )
    return ""
