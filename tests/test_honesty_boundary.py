"""The honesty boundary (DESIGN.md §3): who may import pybullet, the simulator and ground truth.

Parsed with ``ast`` (imports inside functions count too). Skills, behaviours, trees and the
core (``suture_bt/`` except the front-door modules) must not import pybullet or
``suture_bt.sim``; ``suture_bt.sim.ground_truth`` may be imported only by front-door modules,
tests and benchmarks (and by nothing in ``sim/`` other than itself). Relative imports are
resolved by the installed module name (``skills/x.py`` is ``suture_bt.skills.x``).

Skills, behaviours and trees must also not introspect their way around the interface views
(``importlib``, ``eval``, ``__closure__``, ``getattr(x, "_...")`` ...) nor read the
attributes that carry ground truth on simulator objects (``honesty_helpers.TRUTH_NAMES``).
Finally, the views handed to skills reach no simulator object by plain attribute access.
The checkers live in ``honesty_helpers``; the tests below also prove that they catch what
they should.
"""

import types
from dataclasses import dataclass
from pathlib import Path

import pytest
from honesty_helpers import (
    RESTRICTED_DIRS,
    ROOT,
    TRUTH_NAMES,
    forbidden_import,
    import_offences,
    imported_modules,
    is_front_door,
    module_name,
    reachable_sim_objects,
    restricted_files,
    source_offences,
)


# ---------------------------------------------------------------------- the boundary itself
def test_core_skills_behaviours_trees_do_not_import_the_simulator():
    offenders = []
    for path in restricted_files():
        bad = import_offences(path)
        if bad:
            offenders.append(f"{path.relative_to(ROOT)}: {', '.join(bad)}")
    assert not offenders, "honesty boundary broken:\n" + "\n".join(offenders)


def test_ground_truth_only_from_front_door_tests_and_benchmarks():
    allowed_roots = (ROOT / "tests", ROOT / "benchmarks")
    offenders = []
    for path in ROOT.rglob("*.py"):
        if any(part.startswith(".") for part in path.relative_to(ROOT).parts):
            continue
        if path.is_relative_to(ROOT / "build") or path == ROOT / "sim" / "ground_truth.py":
            continue
        if any(path.is_relative_to(r) for r in allowed_roots):
            continue
        if path.is_relative_to(ROOT / "suture_bt") and is_front_door(path):
            continue
        if any(n.startswith("suture_bt.sim.ground_truth") for n in imported_modules(path)):
            offenders.append(str(path.relative_to(ROOT)))
    assert not offenders, "ground truth imported outside the front door:\n" + "\n".join(offenders)


def test_skills_behaviours_trees_neither_introspect_nor_read_truth():
    offenders = []
    for d in RESTRICTED_DIRS:
        for path in sorted((ROOT / d).rglob("*.py")):
            offenders += [f"{path.relative_to(ROOT)}:{o}" for o in source_offences(path)]
    assert not offenders, "honesty boundary broken:\n" + "\n".join(offenders)


# ---------------------------------------------------------------------- the checkers work
def test_the_checker_catches_violations(tmp_path):
    # The parser sees plain, from- and function-local imports.
    f = tmp_path / "x.py"
    f.write_text(
        "def f():\n    import pybullet as p\n"
        "from suture_bt.sim import ground_truth\nimport suture_bt.sim.world\n"
    )
    names = imported_modules(f)
    assert "pybullet" in names
    assert "suture_bt.sim.ground_truth" in names
    assert "suture_bt.sim.world" in names
    assert all(forbidden_import(n) for n in ("pybullet", "suture_bt.sim.world", "suture_bt.sim"))
    assert not forbidden_import("suture_bt.simulation_helpers")


def _fake_file(root: Path, rel: str, source: str) -> Path:
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(source)
    return path


@pytest.mark.parametrize(
    "rel, source, expected",
    [
        ("skills/x.py", "from ..sim import ground_truth\n", "suture_bt.sim.ground_truth"),
        ("skills/x.py", "from .. import sim\n", "suture_bt.sim"),
        ("skills/sub/y.py", "from ...sim.world import World\n", "suture_bt.sim.world"),
        ("skills/__init__.py", "from ..sim import world\n", "suture_bt.sim.world"),
        ("behaviours/b.py", "from ..sim.camera import StereoEndoscope\n", "suture_bt.sim.camera"),
        ("trees/t.py", "def f():\n    from ..sim import scene\n", "suture_bt.sim.scene"),
        ("suture_bt/planning/p.py", "from ..sim import world\n", "suture_bt.sim.world"),
        ("suture_bt/x.py", "from .sim import world\n", "suture_bt.sim.world"),
    ],
)
def test_relative_imports_resolve_by_installed_name(tmp_path, rel, source, expected):
    path = _fake_file(tmp_path, rel, source)
    assert path in restricted_files(tmp_path)
    assert expected in import_offences(path, tmp_path)


def test_relative_imports_inside_sim_resolve_too(tmp_path):
    path = _fake_file(tmp_path, "sim/faults.py", "from . import ground_truth\n")
    assert "suture_bt.sim.ground_truth" in imported_modules(path, tmp_path)
    assert module_name(path, tmp_path) == ("suture_bt.sim.faults", False)
    assert module_name(tmp_path / "sim/__init__.py", tmp_path) == ("suture_bt.sim", True)


VIOLATIONS = {
    "importlib": "import importlib\n",
    "importlib_from": "from importlib import import_module\n",
    "inspect": "import inspect\n",
    "gc": "import gc\n",
    "dunder_import": "m = __import__('suture_bt.sim')\n",
    "exec": "exec('x = 1')\n",
    "eval": "y = eval('1 + 1')\n",
    "compile": "c = compile('1', 'f', 'eval')\n",
    "vars": "d = vars(arm)\n",
    "getattr_private": "q = getattr(arm, '_servo')\n",
    "getattr_private2": "q = getattr(arm, '_ArmView__ops')\n",
    "setattr_private": "setattr(arm, '_x', 1)\n",
    "getattr_truth": "b = getattr(arm, 'body')\n",
    "getattr_computed": "q = getattr(arm, '_' + 'servo')\n",
    "attrgetter": "from operator import attrgetter\nf = attrgetter('jaw._angle')\n",
    "self": "p = arm.measured_jp.__self__\n",
    "closure": "c = arm._ops.__closure__[0].cell_contents\n",
    "globals": "g = f.__globals__\n",
    "dict": "d = arm.__dict__\n",
    "wrapped": "w = f.__wrapped__\n",
    "traceback": "try:\n    pass\nexcept Exception as e:\n    e.__traceback__.tb_frame\n",
    "mangled": "o = arm._ArmView__ops\n",
}
VIOLATIONS |= {f"truth_{n}": f"v = thing.{n}\n" for n in sorted(TRUTH_NAMES)}
VIOLATIONS |= {
    "gt_import": "from suture_bt.sim.ground_truth import GroundTruth\n",
    "gt_relative": "from ..sim import ground_truth\n",
    "gt_name": "def f(world):\n    return GroundTruth(world)\n",
    "gt_param": "def f(ground_truth):\n    pass\n",
    "truth_store": "def f(view, x):\n    view.scene = x\n",
}


@pytest.mark.parametrize("key", sorted(VIOLATIONS))
@pytest.mark.parametrize("folder", RESTRICTED_DIRS)
def test_the_source_checker_catches_each_violation(tmp_path, folder, key):
    path = _fake_file(tmp_path, f"{folder}/x.py", VIOLATIONS[key])
    assert source_offences(path, tmp_path), f"{key!r} in {folder}/ not flagged"


def test_the_source_checker_passes_ordinary_behaviour_code(tmp_path):
    source = """
import numpy as np
import py_trees
from py_trees.common import Status
from ..skills.base import Skill


class Approach(py_trees.behaviour.Behaviour):
    def __init__(self, name: str, arm_name: str):
        super().__init__(name=name)
        self.arm_name = arm_name
        self.__retries = 0

    def setup(self, **kwargs):
        self.arms = kwargs["context"].arms
        self.bb = self.attach_blackboard_client(name=self.name)
        self.bb.register_key("goal", access=py_trees.common.Access.READ)

    def update(self) -> Status:
        arm = self.arms[self.arm_name]
        if not arm.is_busy():
            arm.move_cp(self.bb.get("goal"))
        self.feedback_message = f"{self.__class__.__name__}: {np.round(arm.measured_jp(), 3)}"
        return Status.RUNNING
"""
    path = _fake_file(tmp_path, "behaviours/approach.py", source)
    assert source_offences(path, tmp_path) == []
    assert import_offences(path, tmp_path) == []


# ---------------------------------------------------------------------- object graph
@pytest.fixture(scope="module")
def headless_world():
    from suture_bt.sim.world import World

    with World.from_scene(None, with_camera=False) as world:
        yield world


def test_the_views_reach_no_simulator_object(headless_world):
    from suture_bt.runtime.views import views_of

    views = views_of(headless_world)
    assert views.camera is None  # no camera in this world
    assert reachable_sim_objects(views) == []
    assert reachable_sim_objects(views.arms) == []
    assert reachable_sim_objects(views.psm1.jaw) == []


def test_the_raw_world_reaches_simulator_objects(headless_world):
    found = dict(reachable_sim_objects(headless_world))
    assert found[""] is headless_world
    assert found[".psm1"] is headless_world.psm1
    assert found[".psm1.body"] is headless_world.psm1.body
    assert ".psm1._servo" in found and ".clock" in found


@dataclass
class _Fields:
    item: object


class _Slots:
    __slots__ = ("__hidden", "plain")

    def __init__(self, obj):
        self.__hidden = obj
        self.plain = None


@pytest.mark.parametrize(
    "wrap, path",
    [
        (lambda o: types.SimpleNamespace(a=o), ".a"),
        (lambda o: {"k": o}, "['k']"),
        (lambda o: [0, (1, o)], "[1][1]"),
        (lambda o: {o}, "[0]"),
        (lambda o: _Fields(o), ".item"),
        (lambda o: _Slots(o), "._Slots__hidden"),
    ],
)
def test_the_walk_sees_through_containers(headless_world, wrap, path):
    found = reachable_sim_objects(wrap(headless_world.clock))
    assert found == [(path, headless_world.clock)]


def test_the_walk_skips_functions_and_respects_depth(headless_world):
    clock = headless_world.clock
    assert reachable_sim_objects(types.SimpleNamespace(f=lambda: clock)) == []
    nested = types.SimpleNamespace(a=types.SimpleNamespace(b=types.SimpleNamespace(c=clock)))
    assert reachable_sim_objects(nested, max_depth=2) == []
    assert reachable_sim_objects(nested, max_depth=3) == [(".a.b.c", clock)]
