"""Interface-only views (suture_bt.runtime.views): exactly the Protocols, copies, no way back."""

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from suture_bt.interfaces import (
    Clock,
    JawInterface,
    JointState,
    PSMInterface,
    StereoCameraInterface,
    StereoCameraModel,
    StereoFrame,
)
from suture_bt.runtime import views as views_module
from suture_bt.runtime.views import (
    ArmView,
    CameraView,
    ClockView,
    JawView,
    WorldViews,
    views_of,
)

ARM_API = {
    "name",
    "jaw",
    "measured_js",
    "measured_jp",
    "measured_jv",
    "setpoint_jp",
    "servo_jp",
    "move_jp",
    "measured_cp",
    "setpoint_cp",
    "servo_cp",
    "move_cp",
    "is_busy",
    "base_frame",
}
JAW_API = {"open", "close", "measured_jp", "setpoint_jp", "move_jp", "servo_jp", "is_busy"}


def _public(obj) -> set[str]:
    return {n for n in dir(obj) if not n.startswith("_")}


# ---------------------------------------------------------------------- fakes
class FakeJaw:
    def __init__(self):
        self.angle = np.array([0.5])
        self.calls = []

    def open(self, angle=1.0):
        self.calls.append(("open", angle))
        return "internal"

    def close(self):
        self.calls.append(("close",))

    def measured_jp(self):
        return self.angle

    def setpoint_jp(self):
        return self.angle

    def move_jp(self, jp):
        self.calls.append(("move_jp", jp))

    def servo_jp(self, jp):
        self.calls.append(("servo_jp", jp))

    def is_busy(self):
        return 0


class FakePSM:
    """Exposes its internals as arrays it keeps (what a careless view would hand out)."""

    secret = "truth"

    def __init__(self, name="psmX"):
        self.name = name
        self.jaw = FakeJaw()
        self.q = np.arange(6.0)
        self.T = np.eye(4)
        self.calls = []

    def measured_js(self):
        return JointState(self.q, self.q, self.q)

    def measured_jp(self):
        return self.q

    def measured_jv(self):
        return self.q

    def setpoint_jp(self):
        return self.q

    def servo_jp(self, jp):
        self.calls.append(("servo_jp", jp))
        return self  # a leak, were it passed on

    def move_jp(self, jp):
        self.calls.append(("move_jp", jp))
        return self

    def measured_cp(self):
        return self.T

    def setpoint_cp(self):
        return self.T

    def servo_cp(self, cp):
        self.calls.append(("servo_cp", cp))

    def move_cp(self, cp):
        self.calls.append(("move_cp", cp))

    def is_busy(self):
        return []

    def base_frame(self):
        return self.T


class FakeClock:
    def __init__(self):
        self.t = 1

    def now(self):
        return self.t


class FakeWorld:
    def __init__(self):
        self.psm1 = FakePSM("psm1")
        self.psm2 = FakePSM("psm2")
        self.camera = None
        self.clock = FakeClock()


# ---------------------------------------------------------------------- with fakes
def test_arm_view_exposes_exactly_the_interface():
    view = ArmView(FakePSM())
    assert isinstance(view, PSMInterface)
    assert isinstance(view.jaw, JawInterface) and isinstance(view.jaw, JawView)
    assert _public(view) == ARM_API
    assert _public(view.jaw) == JAW_API
    assert not hasattr(view, "__dict__") and not hasattr(view.jaw, "__dict__")
    assert not hasattr(view, "secret") and not hasattr(view, "calls")
    assert view.name == "psmX" and repr(view) == "ArmView('psmX')"


def test_returned_arrays_are_copies():
    psm = FakePSM()
    view = ArmView(psm)
    for read in ("measured_jp", "measured_jv", "setpoint_jp"):
        out = getattr(view, read)()
        out[:] = -1
        assert np.array_equal(psm.q, np.arange(6.0)), read
    for read in ("measured_cp", "setpoint_cp", "base_frame"):
        getattr(view, read)()[:] = 7
        assert np.array_equal(psm.T, np.eye(4)), read
    js = view.measured_js()
    js.position[:] = js.velocity[:] = js.effort[:] = -1
    assert np.array_equal(psm.q, np.arange(6.0))
    view.jaw.measured_jp()[:] = 9
    view.jaw.setpoint_jp()[:] = 9
    assert psm.jaw.angle[0] == 0.5


def test_commands_pass_through_and_return_nothing():
    psm = FakePSM()
    view = ArmView(psm)
    goal = np.eye(4)
    assert view.servo_jp([0.1] * 6) is None
    assert view.move_jp([0.2] * 6) is None
    assert view.servo_cp(goal) is None
    assert view.move_cp(goal) is None
    assert [c[0] for c in psm.calls] == ["servo_jp", "move_jp", "servo_cp", "move_cp"]
    assert view.is_busy() is False
    assert view.jaw.open() is None  # the arm's own default angle
    view.jaw.open(0.3)
    view.jaw.close()
    view.jaw.move_jp(0.2)
    view.jaw.servo_jp(0.1)
    assert psm.jaw.calls == [
        ("open", 1.0),
        ("open", 0.3),
        ("close",),
        ("move_jp", 0.2),
        ("servo_jp", 0.1),
    ]
    assert view.jaw.is_busy() is False


def test_views_are_read_only():
    view = ArmView(FakePSM())
    with pytest.raises(AttributeError):
        view.name = "other"
    with pytest.raises(AttributeError):
        view.jaw = None
    with pytest.raises(AttributeError):
        view._ops = None
    with pytest.raises(AttributeError):
        del view._ops
    with pytest.raises(AttributeError):
        view.jaw.extra = 1


def test_a_wrong_object_fails_at_wiring_time_naming_what_is_missing():
    class NoMoves(FakePSM):
        move_cp = None

    with pytest.raises(TypeError, match="ArmView: NoMoves has no move_cp"):
        ArmView(NoMoves())
    with pytest.raises(TypeError, match="ClockView: object has no now"):
        ClockView(object())
    with pytest.raises(TypeError, match="CameraView"):
        CameraView(object())


def test_clock_view_and_world_views_from_fakes():
    world = FakeWorld()
    views = views_of(world)
    assert isinstance(views, WorldViews)
    assert isinstance(views.clock, Clock) and _public(views.clock) == {"now"}
    assert views.clock.now() == 1.0 and isinstance(views.clock.now(), float)
    world.clock.t = 2.5
    assert views.clock.now() == 2.5
    assert views.camera is None
    assert views.arms == {"psm1": views.psm1, "psm2": views.psm2}
    assert views.psm2.name == "psm2"
    with pytest.raises(AttributeError):
        views.psm1 = views.psm2  # frozen
    views.arms["psm1"] = None  # a fresh dict: the views keep theirs
    assert views.arms["psm1"] is views.psm1


def test_views_module_imports_neither_pybullet_nor_the_simulator():
    tree = ast.parse(Path(views_module.__file__).read_text())
    imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any(m.startswith(("pybullet", "suture_bt.sim")) for m in imported)
    code = (
        "import sys, suture_bt.runtime.views\n"
        "bad = [m for m in sys.modules if m.startswith(('pybullet', 'suture_bt.sim'))]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


# ---------------------------------------------------------------------- with a real world
@pytest.fixture(scope="module")
def world():
    from suture_bt.sim.world import World

    with World.from_scene(None, with_camera=False) as w:
        yield w


def test_real_arms_satisfy_the_protocols_and_report_what_the_arm_reports(world):
    views = views_of(world)
    for name, view in views.arms.items():
        psm = getattr(world, name)
        assert isinstance(view, PSMInterface) and _public(view) == ARM_API
        assert view.name == name
        assert np.array_equal(view.measured_jp(), psm.measured_jp())
        assert np.array_equal(view.setpoint_cp(), psm.setpoint_cp())
        assert np.array_equal(view.base_frame(), psm.base_frame())
        assert np.array_equal(view.jaw.measured_jp(), psm.jaw.measured_jp())
        assert not hasattr(view, "body") and not hasattr(view, "_true_jp")
    assert views.camera is None
    assert views.clock.now() == world.clock.now()


def test_real_arm_moves_through_its_view(world):
    arm = views_of(world).psm1
    start = arm.setpoint_jp()
    goal = start + np.array([0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
    arm.move_jp(goal)
    assert arm.is_busy()
    world.step(0.5)
    assert not arm.is_busy()
    assert np.allclose(arm.setpoint_jp(), goal)
    arm.setpoint_jp()[:] = 0  # a copy: the arm's set-point is untouched
    assert np.allclose(world.psm1.setpoint_jp(), goal)
    arm.move_jp(start)
    world.step(0.5)


def test_camera_view_captures_and_copies_the_model():
    from suture_bt.sim.scene import scene_from_dict
    from suture_bt.sim.world import World

    scene = scene_from_dict({"camera": {"width": 160, "height": 120}})
    with World.from_scene(scene, with_camera=True) as w:
        cam = views_of(w).camera
        assert isinstance(cam, CameraView) and isinstance(cam, StereoCameraInterface)
        assert _public(cam) == {"capture", "model"}
        assert not hasattr(cam, "render") and not hasattr(cam, "rng")
        w.step(0.01)
        frame = cam.capture()
        assert isinstance(frame, StereoFrame)
        assert frame.left.shape == (120, 160, 3) and frame.left.dtype == np.uint8
        assert frame.stamp == pytest.approx(w.clock.now())
        model = cam.model
        assert isinstance(model, StereoCameraModel)
        assert np.array_equal(model.left.T_world_cam, w.camera.model.left.T_world_cam)
        model.left.T_world_cam[:] = 0  # a copy: the endoscope's model is untouched
        assert w.camera.model.left.T_world_cam[3, 3] == 1.0
        assert cam.model is not w.camera.model
