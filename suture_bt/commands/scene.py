"""``suture-bt scene``: build a world from a scene file, write the stereo pair, print a summary."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from suture_bt.sim import ground_truth
from suture_bt.sim.quiet import quiet_fd
from suture_bt.sim.scene import load_scene
from suture_bt.sim.world import World
from suture_bt.transforms import matrix_to_rpy


def register(subparsers) -> None:
    p = subparsers.add_parser("scene", help="render a scene and print its summary")
    add_scene_arguments(p)
    p.set_defaults(func=run)


def add_scene_arguments(p: argparse.ArgumentParser) -> None:
    """--scene and --out, shared with ``run``."""
    p.add_argument("--scene", metavar="FILE", help="scene YAML (default: the embedded SRC scene)")
    p.add_argument("--out", metavar="DIR", default="out", help="where left.png/right.png go")


def _fmt(v, scale: float = 1.0, digits: int = 1) -> str:
    return "(" + ", ".join(f"{x * scale:+.{digits}f}" for x in v) + ")"


def summary(world: World) -> str:
    """A plain-text table of the scene: arm bases, ports, needle and (ground-truth) offsets."""
    gt = ground_truth.GroundTruth(world)
    lines = ["arm base (RCM) poses, world frame: position mm, rpy deg"]
    for name, arm in world.arms.items():
        T = arm.base_frame()
        lines.append(
            f"  {name:<6} {_fmt(T[:3, 3], 1e3)}  rpy {_fmt(np.rad2deg(matrix_to_rpy(T[:3, :3])))}"
        )
    lines.append("ports, world frame: position mm, outward normal")
    for port in world.task.phantom.ports():
        lines.append(f"  {port.name:<6} {_fmt(port.position, 1e3, 2)}  n {_fmt(port.normal, 1, 3)}")
    if world.needle is not None:
        T = gt.needle_pose()
        holder = gt.needle_holder() or "nobody (free)"
        lines.append("needle pose [GROUND TRUTH], world frame")
        lines.append(
            f"  position mm {_fmt(T[:3, 3], 1e3, 2)}  rpy deg "
            f"{_fmt(np.rad2deg(matrix_to_rpy(T[:3, :3])))}  held by {holder}"
        )
    else:
        lines.append("needle: not in this build of the world")
    lines.append("hidden joint offsets [GROUND TRUTH]: joint 1 deg, joint 2 deg, joint 3 mm")
    for name in world.arms:
        dq = gt.joint_offset(name)
        lines.append(
            f"  {name:<6} ({np.rad2deg(dq[0]):+.2f}, {np.rad2deg(dq[1]):+.2f}, {dq[2] * 1e3:+.2f})"
        )
    return "\n".join(lines)


def write_stereo_pair(world: World, out: Path) -> list[Path]:
    """Render both eyes and write them as PNG; returns the paths (empty without a camera)."""
    import cv2

    if world.camera is None:
        return []
    out.mkdir(parents=True, exist_ok=True)
    frame = world.camera.capture()
    paths = []
    for eye, rgb in (("left", frame.left), ("right", frame.right)):
        path = out / f"{eye}.png"
        if not cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1])):
            raise OSError(f"cannot write {path}")
        paths.append(path)
    return paths


def settle(world: World, seconds: float = 0.5) -> None:
    """Let the scene settle (a resting needle comes to rest) before rendering."""
    world.step(seconds)


def run(args, preface: str | None = None) -> int:
    scene = load_scene(args.scene)
    if preface:
        print(preface)
    # pybullet's EGL plugin chats on stderr; keep stderr for our own one-line errors.
    with quiet_fd(2):
        world = World.from_scene(scene)
    with world:
        with quiet_fd(2):
            settle(world)
            paths = write_stereo_pair(world, Path(args.out))
        print(summary(world))
        cam = scene.camera
        if paths:
            print(f"stereo pair {cam.width}x{cam.height}: " + ", ".join(str(p) for p in paths))
        else:
            print("stereo pair: no camera in this build of the world, nothing written")
    return 0
