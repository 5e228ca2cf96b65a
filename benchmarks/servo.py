"""Benchmark: joint tracking error of the low-level servo alone vs. with the high-level PI loop.

Across plants: the robot is not the model, so the low-level servo's bandwidth and friction
are swept (``--bandwidths``, ``--frictions``; every joint of both arms set to the value) and
the default (adaptive) PI loop is compared with the fixed-gain loop tuned for the nominal
6 Hz servo (``PIGains(adaptive=False)``). The controller is told nothing about the plant.

Both arms of the real simulated World (servo error model on, zero joint offset) run the same
fixed, seeded set of random in-limit joint moves (trapezoidal timing at the default joint
limits), each followed by a hold. The true joints (ground truth) are compared with the desired
joints at every PI period. Baseline: the desired joints go straight to the low-level servo;
PI: they go through :class:`suture_bt.control.PIServo`. Figures: revolute joints in degrees,
the prismatic insertion joint in mm; ``steady_state`` is the mean |error| over the last 0.1 s
of each hold; ``reduction`` = 1 − steady_state_pi / steady_state_lowlevel (the fraction of the
low-level error removed, the seed's 98 %); ``reduction_rms`` the same for the RMS error.

    .venv/bin/python benchmarks/servo.py [--json PATH] [--moves N] [--hold S] [--seed K]
        [--bandwidths 3,6,12] [--frictions 0.5,1.5,2.5]
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from suture_bt.control import PIGains, PIServo
from suture_bt.kinematics import JOINT_LIMITS
from suture_bt.planning import JointMove
from suture_bt.sim.ground_truth import GroundTruth
from suture_bt.sim.scene import scene_from_dict
from suture_bt.sim.world import World

ARMS = ("psm1", "psm2")
REVOLUTE = [0, 1, 3, 4, 5]
PRISMATIC = 2
#: Random targets are drawn inside this fraction of each joint range (insertion: 6-20 cm).
RANGE_FRACTION = 0.7
SETTLE_WINDOW = 0.1


def random_targets(rng: np.random.Generator, n: int) -> np.ndarray:
    """n joint vectors inside the limits, away from the extremes."""
    lo, hi = JOINT_LIMITS[:, 0] * RANGE_FRACTION, JOINT_LIMITS[:, 1] * RANGE_FRACTION
    q = rng.uniform(lo, hi, size=(n, 6))
    q[:, 2] = rng.uniform(0.06, 0.20, size=n)
    return q


def run(
    pi: bool,
    targets: dict[str, np.ndarray],
    hold: float,
    servo: dict | None = None,
    gains: PIGains | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """Errors (true − desired) per arm: all samples, and the settled samples of each hold.

    ``servo`` overrides the scene's low-level servo section (the plant); ``gains`` the PI's.
    """
    scene = scene_from_dict({"servo": {"error_model": True, **(servo or {})}})
    with World.from_scene(scene, with_camera=False) as world:
        truth = GroundTruth(world)
        servos = {a: PIServo(getattr(world, a), enabled=pi, gains=gains) for a in ARMS}
        for s in servos.values():
            s.reset()
            s.attach(world.add_periodic)
        dt = servos["psm1"].dt
        samples = {a: [] for a in ARMS}
        settled = {a: [] for a in ARMS}
        for k in range(len(targets["psm1"])):
            moves = {a: JointMove(servos[a], targets[a][k]) for a in ARMS}
            for a in ARMS:
                st = moves[a].start()
                if st.failed:
                    raise RuntimeError(f"{a} move {k}: {st.reason}")
                servos[a].follow(moves[a])  # the servo advances the move at its rate
            duration = max(m.duration for m in moves.values()) + hold
            n = int(round(duration / dt))
            for i in range(n):
                world.step(dt)
                for a in ARMS:
                    e = truth.joint_positions(a) - servos[a].setpoint_jp()
                    samples[a].append(e)
                    if i >= n - int(round(SETTLE_WINDOW / dt)):
                        settled[a].append(e)
        return {a: {"all": np.array(samples[a]), "settled": np.array(settled[a])} for a in ARMS}


def figures(low: dict[str, np.ndarray], pi: dict[str, np.ndarray]) -> dict[str, float]:
    """The benchmark figures for one arm."""

    def rms(e, j, scale):
        return float(np.sqrt(np.mean((e[:, j] * scale) ** 2)))

    def ss(e, j, scale):
        return float(np.mean(np.abs(e[:, j] * scale)))

    deg, mm = np.rad2deg(1.0), 1e3
    out = {
        "rms_error_lowlevel_deg": rms(low["all"], REVOLUTE, deg),
        "rms_error_pi_deg": rms(pi["all"], REVOLUTE, deg),
        "steady_state_error_lowlevel_deg": ss(low["settled"], REVOLUTE, deg),
        "steady_state_error_pi_deg": ss(pi["settled"], REVOLUTE, deg),
        "rms_error_lowlevel_mm": rms(low["all"], [PRISMATIC], mm),
        "rms_error_pi_mm": rms(pi["all"], [PRISMATIC], mm),
        "steady_state_error_lowlevel_mm": ss(low["settled"], [PRISMATIC], mm),
        "steady_state_error_pi_mm": ss(pi["settled"], [PRISMATIC], mm),
    }
    out["reduction"] = (
        1.0 - out["steady_state_error_pi_deg"] / out["steady_state_error_lowlevel_deg"]
    )
    out["reduction_mm"] = (
        1.0 - out["steady_state_error_pi_mm"] / out["steady_state_error_lowlevel_mm"]
    )
    out["reduction_rms"] = 1.0 - out["rms_error_pi_deg"] / out["rms_error_lowlevel_deg"]
    out["reduction_rms_mm"] = 1.0 - out["rms_error_pi_mm"] / out["rms_error_lowlevel_mm"]
    return out


def sweep(
    targets: dict[str, np.ndarray], hold: float, bandwidths: list[float], frictions: list[float]
) -> list[dict]:
    """Steady-state reduction per plant (bandwidth × friction), adaptive vs fixed gains."""
    rows = []
    for bw in bandwidths:
        for fr in frictions:
            plant = {
                "bandwidth_hz": bw,
                "revolute_friction_deg": fr,
                "prismatic_friction_mm": 0.1 * fr / 1.5,
            }
            low = run(False, targets, hold, plant)
            row = {"bandwidth_hz": bw, "friction_deg": fr}
            for name, gains in (("adaptive", None), ("fixed", PIGains(adaptive=False))):
                pi = run(True, targets, hold, plant, gains)
                for a in ARMS:
                    f = figures(low[a], pi[a])
                    row[f"{a}_{name}"] = f["reduction"]
                    row[f"{a}_{name}_mm"] = f["reduction_mm"]
                    row[f"{a}_lowlevel_deg"] = f["steady_state_error_lowlevel_deg"]
            rows.append(row)
            print(
                f"{bw:6.1f} Hz {fr:5.2f}°  "
                + "  ".join(
                    f"{a}: {row[f'{a}_adaptive']:7.2%} ({row[f'{a}_adaptive_mm']:7.2%}) "
                    f"fixed {row[f'{a}_fixed']:7.2%} ({row[f'{a}_fixed_mm']:7.2%})"
                    for a in ARMS
                ),
                flush=True,
            )
    return rows


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v.strip()]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", metavar="PATH", help="write the figures as JSON")
    p.add_argument("--moves", type=int, default=8, help="random moves per arm (default 8)")
    p.add_argument("--hold", type=float, default=1.0, help="hold after each move, s")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--bandwidths", default="3,6,12", help="plant bandwidths to sweep, Hz")
    p.add_argument("--frictions", default="0.5,1.5,2.5", help="revolute frictions to sweep, deg")
    args = p.parse_args(argv)
    if args.moves < 1 or args.hold < 2 * SETTLE_WINDOW:
        p.error(f"need --moves ≥ 1 and --hold ≥ {2 * SETTLE_WINDOW} s")
    rng = np.random.default_rng(args.seed)
    targets = {a: random_targets(rng, args.moves) for a in ARMS}
    t0 = time.perf_counter()
    low = run(False, targets, args.hold)
    pi = run(True, targets, args.hold)
    result = {
        "config": {"moves": args.moves, "hold_s": args.hold, "seed": args.seed, "pi_rate_hz": 200},
        "wall_s": time.perf_counter() - t0,
    }
    for a in ARMS:
        result[a] = figures(low[a], pi[a])
    keys = list(result["psm1"])
    print(f"{'figure':34s} {'psm1':>10s} {'psm2':>10s}")
    for k in keys:
        print(f"{k:34s} {result['psm1'][k]:10.4f} {result['psm2'][k]:10.4f}")
    print(
        "\nsteady-state error removed per plant, revolute (prismatic); adaptive = default loop, "
        "fixed = gains of the nominal 6 Hz plant"
    )
    result["sweep"] = sweep(targets, args.hold, _floats(args.bandwidths), _floats(args.frictions))
    result["wall_s"] = time.perf_counter() - t0
    print(f"wall time {result['wall_s']:.1f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
