"""Simulation speed: physics steps/s, stereo render time, closed-form IK time.

    python benchmarks/sim_speed.py [--json PATH] [--steps N] [--renders N] [--ik N]

* ``physics_steps_per_s``: 1 kHz physics ticks per wall second of the full default scene with
  both arms moving (servo model on) and the needle held in PSM2's jaw; the same with the
  needle free on the tissue is reported as ``physics_steps_per_s_needle_resting``.
* ``render_ms_per_stereo_pair``: one ``capture()`` (both eyes) at the scene's default
  resolution (1920×1080, tiled) and at 640×480.
* ``ik_us_per_solve``: ``inverse_kinematics`` on random reachable tip poses.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

from suture_bt.kinematics import JOINT_LIMITS, forward_kinematics, inverse_kinematics
from suture_bt.sim.camera import StereoEndoscope
from suture_bt.sim.rendering import load_renderer
from suture_bt.sim.scene import default_scene, scene_from_dict
from suture_bt.sim.world import World


def physics_steps_per_s(needle_start: str, steps: int) -> float:
    """Ticks per wall second with both arms moving back and forth."""
    with World.from_scene(scene_from_dict({"needle": {"start": needle_start}})) as w:
        w.step(0.2)  # settle
        q1, q2 = w.psm1.setpoint_jp(), w.psm2.setpoint_jp()
        delta = np.array([0.1, 0.05, 0.01, 0.2, 0.1, 0.1])
        t0 = time.perf_counter()
        done, sign = 0, 1.0
        while done < steps:
            w.psm1.move_jp(q1 + sign * delta)
            w.psm2.move_jp(q2 + sign * delta)
            chunk = min(500, steps - done)
            w.step(chunk * w.dt)
            done += chunk
            sign = -sign
        return steps / (time.perf_counter() - t0)


def render_ms_per_stereo_pair(width: int, height: int, renders: int) -> tuple[float, str]:
    """Mean wall time of one stereo capture in the default scene, and the renderer used."""
    with World.from_scene(default_scene(), with_camera=True) as w:
        w.step(0.05)
        cam = StereoEndoscope(w.client, width, height)
        cam.capture()  # warm-up
        t0 = time.perf_counter()
        for _ in range(renders):
            cam.capture()
        return (time.perf_counter() - t0) / renders * 1e3, load_renderer(w.client)


def ik_us_per_solve(n: int, seed: int = 0) -> float:
    """Mean wall time of one closed-form IK solve (random in-limit poses, q3 > 0.03 m)."""
    rng = np.random.default_rng(seed)
    lo, hi = JOINT_LIMITS[:, 0].copy(), JOINT_LIMITS[:, 1].copy()
    lo[2] = 0.03
    poses = [forward_kinematics(rng.uniform(lo, hi)) for _ in range(n)]
    t0 = time.perf_counter()
    for T in poses:
        inverse_kinematics(T)
    return (time.perf_counter() - t0) / n * 1e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", metavar="PATH", help="also write the figures as JSON here")
    ap.add_argument("--steps", type=int, default=5000, help="physics ticks per measurement")
    ap.add_argument("--renders", type=int, default=5, help="stereo captures per resolution")
    ap.add_argument("--ik", type=int, default=2000, help="IK solves")
    args = ap.parse_args(argv)
    if min(args.steps, args.renders, args.ik) < 1:
        ap.error("--steps, --renders and --ik must be positive")
    cam = default_scene().camera
    held = physics_steps_per_s("in_psm2_jaw", args.steps)
    resting = physics_steps_per_s("resting", args.steps)
    render_default, renderer = render_ms_per_stereo_pair(cam.width, cam.height, args.renders)
    render_vga, _ = render_ms_per_stereo_pair(640, 480, args.renders)
    figures = {
        "physics_steps_per_s": round(held, 1),
        "physics_steps_per_s_needle_resting": round(resting, 1),
        "render_ms_per_stereo_pair": {
            f"{cam.width}x{cam.height}": round(render_default, 1),
            "640x480": round(render_vga, 1),
        },
        "ik_us_per_solve": round(ik_us_per_solve(args.ik), 1),
        "renderer": renderer,
        "machine": f"{platform.machine()}, {platform.python_implementation()} "
        f"{platform.python_version()}",
        "counts": {"steps": args.steps, "renders": args.renders, "ik": args.ik},
    }
    rows = [
        ("physics_steps_per_s (both arms + held needle)", f"{held:,.0f}"),
        ("physics_steps_per_s (needle resting)", f"{resting:,.0f}"),
        (
            f"render_ms_per_stereo_pair {cam.width}x{cam.height} ({renderer})",
            f"{render_default:.1f}",
        ),
        (f"render_ms_per_stereo_pair 640x480 ({renderer})", f"{render_vga:.1f}"),
        ("ik_us_per_solve", f"{figures['ik_us_per_solve']:.1f}"),
    ]
    width = max(len(r[0]) for r in rows)
    for name, value in rows:
        print(f"{name:<{width}}  {value:>10}")
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(figures, indent=2) + "\n")
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
