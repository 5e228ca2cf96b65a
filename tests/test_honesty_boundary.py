"""The honesty boundary (DESIGN.md §3): who may import pybullet, the simulator and ground truth.

Parsed with ``ast`` (imports inside functions count too). Skills, behaviours, trees and the
core (``suture_bt/`` except the front-door modules below) must not import pybullet or
``suture_bt.sim``; ``suture_bt.sim.ground_truth`` may be imported only by front-door modules,
tests and benchmarks (and by nothing in ``sim/`` other than itself). Relative imports are
resolved by the installed module name (``skills/x.py`` is ``suture_bt.skills.x``).

Skills, behaviours and trees must also not introspect their way around the interface views
(``importlib``, ``eval``, ``__closure__``, ``getattr(x, "_...")`` ...) nor read the
attributes that carry ground truth on simulator objects. Finally, the views handed to skills
reach no simulator object by plain attribute access (``honesty_helpers``).
"""

import ast
import re
import types
from dataclasses import dataclass
from pathlib import Path

import pytest
from honesty_helpers import reachable_sim_objects

ROOT = Path(__file__).resolve().parents[1]

#: Front-door modules of the core (paths relative to suture_bt/): they wire worlds to trees.
FRONT_DOOR = ("cli.py", "commands/", "runtime/", "evaluation/", "oracle/", "datagen/")
RESTRICTED_DIRS = ("skills", "behaviours", "trees")
#: Folders installed under another name (pyproject package-dir).
INSTALLED_AS = {
    "sim": "suture_bt.sim",
    "skills": "suture_bt.skills",
    "behaviours": "suture_bt.behaviours",
    "trees": "suture_bt.trees",
}

#: Attribute names that carry ground truth (or lead to it) on simulator objects: the true
#: joints and offsets of SimulatedPSM (``_true_jp``, ``_true_offset``, ``_servo``,
#: ``_offset``), its pybullet body (``body``), the World's scene config with the hidden
#: offsets (``scene``), renders and masks (``render``, ``segmentation_masks``), who holds the
#: needle and the grasp check (``needle_holders``, ``needle_holder``, ``last_grasp``), the
#: phantom's records (``phantom_state``, ``crossings``, ``port_crossings``,
#: ``tissue_entries``), the jaw's blocked angle (``min_angle``, ``_angle``), the private
#: handles of wrappers and of the ground-truth API (``_world``, ``_arm``, ``_camera``,
#: ``_clock``), and the ground-truth API itself. Skills, behaviours and trees never read them,
#: not even on their own objects, so a leak cannot hide behind a familiar name.
TRUTH_NAMES = frozenset(
    {
        "_true_jp",
        "_true_offset",
        "body",
        "_servo",
        "_offset",
        "scene",
        "segmentation_masks",
        "render",
        "needle_holders",
        "needle_holder",
        "last_grasp",
        "phantom_state",
        "crossings",
        "port_crossings",
        "tissue_entries",
        "_world",
        "_arm",
        "_camera",
        "_clock",
        "min_angle",
        "_angle",
        "GroundTruth",
        "ground_truth",
    }
)
#: Of those, the ones also forbidden as plain names (variables, imports, parameters).
TRUTH_API_NAMES = frozenset({"GroundTruth", "ground_truth"})
#: Modules that open closures, frames or the import machinery.
INTROSPECTION_MODULES = ("importlib", "inspect", "gc", "ctypes", "builtins")
#: Builtins that run or import code by name, or dump namespaces.
INTROSPECTION_BUILTINS = frozenset(
    {"__import__", "exec", "eval", "compile", "vars", "globals", "locals", "__builtins__"}
)
#: Attributes that lead from a view's methods, or from frames and tracebacks, to its target.
INTROSPECTION_ATTRS = frozenset(
    {
        "__self__",
        "__closure__",
        "__globals__",
        "__dict__",
        "cell_contents",
        "__wrapped__",
        "__func__",
        "__code__",
        "__defaults__",
        "__kwdefaults__",
        "__builtins__",
        "__getattribute__",
        "__subclasses__",
        "__mro__",
        "__bases__",
        "__base__",
        "__objclass__",
        "__reduce__",
        "__reduce_ex__",
        "__traceback__",
        "tb_frame",
        "tb_next",
        "f_back",
        "f_locals",
        "f_globals",
        "gi_frame",
        "cr_frame",
        "_getframe",
    }
)
#: Calls that take an attribute name as a string.
GETATTR_LIKE = frozenset({"getattr", "setattr", "delattr", "hasattr", "attrgetter", "methodcaller"})
#: ``obj._Class__name``: an explicitly name-mangled private attribute of another class.
MANGLED = re.compile(r"_[A-Z]\w*?__\w+")


# ---------------------------------------------------------------------- imports
def _module_name(path: Path, root: Path = ROOT) -> tuple[str, bool]:
    """Installed dotted name of a source file, and whether it is a package (``__init__``)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    is_package = parts[-1] == "__init__"
    if is_package:
        parts.pop()
    if parts and parts[0] in INSTALLED_AS:
        parts[0] = INSTALLED_AS[parts[0]]
    return ".".join(parts), is_package


def _resolve(node: ast.ImportFrom, path: Path, root: Path) -> str:
    """Absolute module of ``from <node.module> import ...`` as Python resolves it."""
    if not node.level:
        return node.module or ""
    module, is_package = _module_name(path, root)
    package = module.split(".") if is_package else module.split(".")[:-1]
    keep = len(package) - (node.level - 1)
    if keep <= 0:
        return f"<beyond the top package>.{node.module or ''}"
    return ".".join(package[:keep] + ([node.module] if node.module else []))


def _imports(path: Path, root: Path = ROOT) -> set[str]:
    """Absolute module names a file imports (``from a.b import c`` gives a.b and a.b.c)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node, path, root)
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def _is_front_door(path: Path, root: Path = ROOT) -> bool:
    rel = path.relative_to(root / "suture_bt").as_posix()
    return any(rel == f or (f.endswith("/") and rel.startswith(f)) for f in FRONT_DOOR)


def _restricted_files(root: Path = ROOT) -> list[Path]:
    files = [p for d in RESTRICTED_DIRS for p in (root / d).rglob("*.py")]
    files += [p for p in (root / "suture_bt").rglob("*.py") if not _is_front_door(p, root)]
    return files


def _forbidden(name: str) -> bool:
    return (
        name == "pybullet"
        or name.startswith(("pybullet.", "pybullet_"))
        or (name == "suture_bt.sim" or name.startswith("suture_bt.sim."))
    )


def _import_offences(path: Path, root: Path = ROOT) -> list[str]:
    return sorted(n for n in _imports(path, root) if _forbidden(n))


# ---------------------------------------------------------------------- introspection, truth
def _callee(node: ast.Call) -> str:
    f = node.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def _attr_name_offence(name: str) -> str | None:
    """Why an attribute name (possibly dotted, as attrgetter takes it) may not be used."""
    for part in name.split("."):
        if part in TRUTH_NAMES:
            return f"truth-bearing attribute {part!r}"
        if part in INTROSPECTION_ATTRS:
            return f"introspection attribute {part!r}"
        if part.startswith("_"):
            return f"private attribute {part!r} by name"
    return None


def _source_offences(path: Path, root: Path = ROOT) -> list[str]:
    """Introspection and truth reads in one skills/behaviours/trees file, as 'line: what'."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found: list[str] = []

    def flag(node: ast.AST, what: str) -> None:
        found.append(f"{getattr(node, 'lineno', '?')}: {what}")

    for module in sorted(_imports(path, root)):
        if module.split(".")[0] in INTROSPECTION_MODULES:
            flag(tree, f"imports {module}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            if node.id in INTROSPECTION_BUILTINS:
                flag(node, f"uses {node.id}")
            if node.id in TRUTH_API_NAMES:
                flag(node, f"names {node.id}")
        elif isinstance(node, ast.arg) and node.arg in TRUTH_API_NAMES:
            flag(node, f"names {node.arg}")
        elif isinstance(node, ast.alias):
            for part in [*node.name.split("."), node.asname or ""]:
                if part in TRUTH_API_NAMES:
                    flag(node, f"imports {node.name}")
        elif isinstance(node, ast.Attribute):
            if node.attr in TRUTH_NAMES:
                flag(node, f"truth-bearing attribute .{node.attr}")
            elif node.attr in INTROSPECTION_ATTRS:  # (re.compile, net.eval() are fine)
                flag(node, f"introspection attribute .{node.attr}")
            elif MANGLED.fullmatch(node.attr) and not node.attr.endswith("__"):
                flag(node, f"name-mangled private attribute .{node.attr}")
        elif isinstance(node, ast.Call) and _callee(node) in GETATTR_LIKE:
            args = node.args if _callee(node) in ("attrgetter", "methodcaller") else node.args[1:2]
            for arg in args[:1] if _callee(node) == "methodcaller" else args:
                if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                    why = _attr_name_offence(arg.value)
                    if why:
                        flag(node, f"{_callee(node)}() of {why}")
                else:
                    flag(node, f"{_callee(node)}() with a computed attribute name")
    return found


# ---------------------------------------------------------------------- the boundary itself
def test_core_skills_behaviours_trees_do_not_import_the_simulator():
    offenders = []
    for path in _restricted_files():
        bad = _import_offences(path)
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
        if path.is_relative_to(ROOT / "suture_bt") and _is_front_door(path):
            continue
        if any(n.startswith("suture_bt.sim.ground_truth") for n in _imports(path)):
            offenders.append(str(path.relative_to(ROOT)))
    assert not offenders, "ground truth imported outside the front door:\n" + "\n".join(offenders)


def test_skills_behaviours_trees_neither_introspect_nor_read_truth():
    offenders = []
    for d in RESTRICTED_DIRS:
        for path in sorted((ROOT / d).rglob("*.py")):
            offenders += [f"{path.relative_to(ROOT)}:{o}" for o in _source_offences(path)]
    assert not offenders, "honesty boundary broken:\n" + "\n".join(offenders)


# ---------------------------------------------------------------------- the checkers work
def test_the_checker_catches_violations(tmp_path):
    # The parser sees plain, from- and function-local imports.
    f = tmp_path / "x.py"
    f.write_text(
        "def f():\n    import pybullet as p\n"
        "from suture_bt.sim import ground_truth\nimport suture_bt.sim.world\n"
    )
    names = _imports(f)
    assert "pybullet" in names
    assert "suture_bt.sim.ground_truth" in names
    assert "suture_bt.sim.world" in names
    assert all(_forbidden(n) for n in ("pybullet", "suture_bt.sim.world", "suture_bt.sim"))
    assert not _forbidden("suture_bt.simulation_helpers")


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
    assert path in _restricted_files(tmp_path)
    assert expected in _import_offences(path, tmp_path)


def test_relative_imports_inside_sim_resolve_too(tmp_path):
    path = _fake_file(tmp_path, "sim/faults.py", "from . import ground_truth\n")
    assert "suture_bt.sim.ground_truth" in _imports(path, tmp_path)
    assert _module_name(path, tmp_path) == ("suture_bt.sim.faults", False)
    assert _module_name(tmp_path / "sim/__init__.py", tmp_path) == ("suture_bt.sim", True)


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
    assert _source_offences(path, tmp_path), f"{key!r} in {folder}/ not flagged"


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
    assert _source_offences(path, tmp_path) == []
    assert _import_offences(path, tmp_path) == []


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
