"""How well the tree knows where along the needle its jaw holds it (the held place).

Each trial is a campaign draw (``suture_bt.campaign.randomize``, the held-out phantom ranges
by default) run as the full suture. At every grasp (the world's holder changes; ground truth
through ``GroundTruth``, the simulator's one truth API) the true place along the needle is
compared with the tree's belief of its in-hand pose (``context.belief``) while that arm holds
the needle: the first belief after the grasp, and every later one. This is the figure behind
the localiser's held-place tolerance (``skills.needle_sensor.HELD_PLACE_TOL``) and the needle
benchmark's spread of the true grasp around it (``needle_task_scenes.HELD_PLACE_SPREAD``).

    python benchmarks/grasp_place.py --seed 4242000 --trials 6 [--json F]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from suture_bt.campaign.randomize import CampaignConfig, Randomization, trial_scene_dict
from suture_bt.runtime.session import Session
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.skills.grasps import held_arc_angle
from suture_bt.transforms import invert


def _watch(session: Session, trial: int, events: list[dict]):
    """An ``on_tick`` that records each grasp's true place and the beliefs during its hold."""
    truth, model = GroundTruth(session.world), session.context.needle
    state = {"holder": None}

    def on_tick(s: Session) -> None:
        holder = truth.needle_holder()
        if holder is None:
            state["holder"] = None
            return
        T_tip_needle = invert(truth.tip_pose_world(holder)) @ truth.needle_pose()
        place = float(held_arc_angle(model, T_tip_needle))
        if holder != state["holder"]:
            state["holder"] = holder
            t = s.context.clock.now()
            events.append({"trial": trial, "arm": holder, "t": t, "beliefs": []})
        ev = events[-1]
        ev["true_deg"] = float(np.degrees(place))  # the hold's (constant without slips)
        b = s.context.belief
        if b is None or b.holder != holder or b.T_tip_needle is None:
            return
        off = 1e3 * model.radius * (float(held_arc_angle(model, b.T_tip_needle)) - place)
        if not ev["beliefs"] or abs(ev["beliefs"][-1] - off) > 1e-9:
            ev["beliefs"].append(off)

    return on_tick


def _stats(values: list[float]) -> dict:
    v = np.abs(np.asarray(values, float))
    if not len(v):
        return {"n": 0, "rms_mm": None, "max_mm": None}
    return {"n": len(v), "rms_mm": float(np.sqrt(np.mean(v**2))), "max_mm": float(v.max())}


def run(seed: int, trials: int, randomization: Randomization) -> dict:
    config = CampaignConfig(seed=seed, randomization=randomization)
    events: list[dict] = []
    for i in range(trials):
        session = Session(scene=trial_scene_dict(config, i))
        try:
            session.run(_watch(session, i, events))
        finally:
            session.close()
    table = {}
    for arm in ("psm1", "psm2"):
        held = [e for e in events if e["arm"] == arm and e["beliefs"]]
        table[arm] = {
            "grasps": len(held),
            "first": _stats([e["beliefs"][0] for e in held]),
            "all": _stats([b for e in held for b in e["beliefs"]]),
        }
    return {"seed": seed, "trials": trials, "by_arm": table, "events": events}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=4242000)
    ap.add_argument("--trials", type=int, default=6)
    ap.add_argument("--phantom-xy", type=float, default=20.0)
    ap.add_argument("--phantom-z", type=float, default=5.0)
    ap.add_argument("--phantom-yaw", type=float, default=20.0)
    ap.add_argument("--phantom-tilt", type=float, default=5.0)
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)
    r = Randomization(
        phantom_xy_mm=args.phantom_xy,
        phantom_z_mm=args.phantom_z,
        phantom_yaw_deg=args.phantom_yaw,
        tilt_deg=args.phantom_tilt,
    )
    res = run(args.seed, args.trials, r)
    print(f"held place: belief - truth along the needle, seed {args.seed}, {args.trials} trials")
    head = ("arm", "grasps", "first RMS", "first max", "all RMS", "all max")
    print("{:6} {:>6} {:>10} {:>10} {:>8} {:>8}".format(*head))
    for arm, row in res["by_arm"].items():
        f, a = row["first"], row["all"]
        if not f["n"]:
            print(f"{arm:6} {0:6d}")
            continue
        print(
            f"{arm:6} {row['grasps']:6d} {f['rms_mm']:8.2f}mm {f['max_mm']:8.2f}mm "
            f"{a['rms_mm']:6.2f}mm {a['max_mm']:6.2f}mm"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
