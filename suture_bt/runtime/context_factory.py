"""Wire a simulated world to the skills: interface views, PI servos, the needle sensor.

The only place (with the oracle) where a world becomes a :class:`TaskContext`; nothing of the
simulator is reachable from what it returns (``tests/test_context_factory.py`` walks it).
"""

from __future__ import annotations

from suture_bt.control import PIServo
from suture_bt.runtime.views import views_of
from suture_bt.skills.context import ArmHandle, TaskContext
from suture_bt.skills.needle_sensor import VisionNeedleSensor


def build_context(world, oracle: bool = False, localizer=None) -> TaskContext:
    """Views of the world's arms, camera and clock, a PI servo per arm run by the world at
    200 Hz, and the vision needle sensor (or, with ``oracle``, the labelled ground-truth one)."""
    views = views_of(world)
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
