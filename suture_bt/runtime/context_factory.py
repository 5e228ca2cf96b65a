"""Wire a simulated world to the skills: interface views, PI servos, the needle sensor.

The only place (with the oracle) where a world becomes a :class:`TaskContext`; nothing of the
simulator is reachable from what it returns (``tests/test_context_factory.py`` walks it).
"""

from __future__ import annotations

from suture_bt.control import PIServo
from suture_bt.perception.needle_localizer import NeedleLocalizer
from suture_bt.perception.unseen_arc import phantom_tissue
from suture_bt.runtime.views import views_of
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.needle_sensor import VisionNeedleSensor


def build_context(world, oracle: bool = False, localizer=None) -> TaskContext:
    """Views of the world's arms, camera and clock, a PI servo per arm run by the world at
    200 Hz, and the vision needle sensor (or, with ``oracle``, the labelled ground-truth one).

    The default localiser knows the task's phantom (the same model the skills plan with), so
    only the tissue where that phantom is may hide the needle's unseen part: without it any
    tissue-coloured pixel may, and a fit that explains a needle piece while its hidden part
    swings over open tissue passes the exposure check (session 18: answers 10-20° off adopted
    in a campaign with dim lighting). Its solid also hides the arc inside it in every fit, so a
    needle going into a port ends its seen wire at the surface (session 24)."""
    views = views_of(world)
    if localizer is None and not oracle:
        stereo = views.camera.model
        tissue = phantom_tissue(world.task.phantom, stereo.left.T_world_cam[:3, 3])
        localizer = NeedleLocalizer(stereo, tissue=tissue)
    arms = {}
    for name, view in views.arms.items():
        servo = PIServo(view)
        servo.reset()
        servo.attach(world.add_periodic)
        arms[name] = ArmHandle(name, view, servo)
    if oracle:
        from suture_bt.oracle import OracleNeedleSensor, offset_oracle

        sensor, offsets = OracleNeedleSensor(world, views.clock), offset_oracle(world)
    else:
        sensor, offsets = VisionNeedleSensor(views.camera, localizer), None
    return TaskContext(
        arms=arms,
        camera=views.camera,
        clock=views.clock,
        phantom=world.task.phantom,
        needle=world.task.needle,
        sensor=sensor,
        offset_oracle=offsets,
    )
