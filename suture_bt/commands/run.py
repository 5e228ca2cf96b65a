"""``suture-bt run``: the main job. Until the suture tree exists it renders the scene headless."""

from __future__ import annotations

from suture_bt.commands import scene as scene_command


def register(subparsers) -> None:
    p = subparsers.add_parser("run", help="the main job (for now: render the scene + summary)")
    scene_command.add_scene_arguments(p)
    p.set_defaults(func=run)


NOTICE = (
    "suture-bt run: the suture behaviour tree does not exist yet; "
    "rendering the scene headless and printing its summary instead"
)


def run(args) -> int:
    return scene_command.run(args, preface=NOTICE)
