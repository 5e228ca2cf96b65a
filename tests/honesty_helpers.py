"""Checkers of the honesty boundary (DESIGN.md §3), shared by tests.

Source checks (``ast``): what a file imports, with relative imports resolved by the installed
module name (``skills/x.py`` is ``suture_bt.skills.x``), and the introspection and
truth-bearing attribute reads that skills, behaviours and trees may not contain.

Object graphs: ``reachable_sim_objects(root)`` walks an object graph the way skill code could
without introspection tricks: instance ``vars()``, ``__slots__`` (private names mangled),
dataclass fields and the items of dicts, lists, tuples and sets. It does not call properties
or methods and does not look inside functions, modules, classes, numpy arrays or primitives
(closures are what the views hide the simulator in; the source checks forbid the
introspection that would open them).
"""

from __future__ import annotations

import ast
import dataclasses
import re
import types
from collections import deque
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np

SIM_PREFIX = "suture_bt.sim"

_OPAQUE = (
    types.ModuleType,
    types.FunctionType,
    types.BuiltinFunctionType,
    types.MethodType,
    types.MethodWrapperType,
    types.WrapperDescriptorType,
    types.MethodDescriptorType,
    types.GeneratorType,
    types.CodeType,
    type,
    np.ndarray,
    np.generic,
    str,
    bytes,
    bytearray,
    int,
    float,
    complex,
    bool,
    range,
    type(None),
    type(Ellipsis),
)


def _is_sim(obj: object) -> bool:
    module = getattr(type(obj), "__module__", "") or ""
    return module == SIM_PREFIX or module.startswith(SIM_PREFIX + ".")


def _dunder(name: str) -> bool:
    return name.startswith("__") and name.endswith("__")


def _slot_names(obj: object) -> Iterator[str]:
    """Attribute names of every ``__slots__`` entry in the MRO (private names mangled)."""
    for cls in type(obj).__mro__:
        slots = cls.__dict__.get("__slots__", ())
        for name in (slots,) if isinstance(slots, str) else slots:
            if _dunder(name):
                continue
            if name.startswith("__"):
                name = f"_{cls.__name__.lstrip('_')}{name}"
            yield name


def _edges(obj: object) -> Iterator[tuple[str, object]]:
    """(label, neighbour) pairs of one object."""
    if isinstance(obj, Mapping):
        for k, v in list(obj.items()):
            yield f"[{k!r}]", v
            yield f"<key {k!r}>", k
        return
    if isinstance(obj, list | tuple | set | frozenset | deque):
        for i, v in enumerate(list(obj)):
            yield f"[{i}]", v
        return
    seen: set[str] = set()
    try:
        attrs = dict(vars(obj))
    except TypeError:
        attrs = {}
    for name, value in attrs.items():
        if not _dunder(name):
            seen.add(name)
            yield f".{name}", value
    names = list(_slot_names(obj))
    if dataclasses.is_dataclass(obj):
        names += [f.name for f in dataclasses.fields(obj)]
    for name in names:
        if name in seen:
            continue
        seen.add(name)
        try:
            value = object.__getattribute__(obj, name)
        except Exception:  # an unset slot, or a field that is not stored
            continue
        yield f".{name}", value


def reachable_sim_objects(root: object, max_depth: int = 8) -> list[tuple[str, object]]:
    """Every object of a ``suture_bt.sim`` type reachable from ``root`` within ``max_depth``
    hops, as (access path, object) pairs, each object once, at its shortest path.

    The root itself counts (path ``""``). The walk goes on through simulator objects too, so
    the paths show what else they expose.
    """
    found: list[tuple[str, object]] = []
    seen = {id(root)}
    alive = [root]  # keeps every visited object alive, so no id() is reused during the walk
    queue: deque[tuple[str, object, int]] = deque([("", root, 0)])
    while queue:
        path, obj, depth = queue.popleft()
        if _is_sim(obj):
            found.append((path, obj))
        if depth >= max_depth or isinstance(obj, _OPAQUE):
            continue
        for label, child in _edges(obj):
            if id(child) not in seen:
                seen.add(id(child))
                alive.append(child)
                queue.append((path + label, child, depth + 1))
    return found


# ---------------------------------------------------------------------- source checks
ROOT = Path(__file__).resolve().parents[1]

#: Front-door modules of the core (paths relative to suture_bt/): they wire worlds to trees
#: and score runs (DESIGN.md §2; evaluation campaigns are part of it).
FRONT_DOOR = (
    "cli.py",
    "commands/",
    "runtime/",
    "evaluation/",
    "campaign/",
    "oracle/",
    "datagen/",
)
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
    """
    _true_jp _true_offset body _servo _offset scene segmentation_masks render needle_holders
    needle_holder last_grasp phantom_state crossings port_crossings tissue_entries _world _arm
    _camera _clock min_angle _angle GroundTruth ground_truth
    """.split()
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
    """
    __self__ __closure__ __globals__ __dict__ cell_contents __wrapped__ __func__ __code__
    __defaults__ __kwdefaults__ __builtins__ __getattribute__ __subclasses__ __mro__ __bases__
    __base__ __objclass__ __reduce__ __reduce_ex__ __traceback__ tb_frame tb_next f_back
    f_locals f_globals gi_frame cr_frame _getframe
    """.split()
)
#: Calls that take an attribute name as a string.
GETATTR_LIKE = frozenset({"getattr", "setattr", "delattr", "hasattr", "attrgetter", "methodcaller"})
#: ``obj._Class__name``: an explicitly name-mangled private attribute of another class.
MANGLED = re.compile(r"_[A-Z]\w*?__\w+")


# ---------------------------------------------------------------------- imports
def module_name(path: Path, root: Path = ROOT) -> tuple[str, bool]:
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
    module, is_package = module_name(path, root)
    package = module.split(".") if is_package else module.split(".")[:-1]
    keep = len(package) - (node.level - 1)
    if keep <= 0:
        return f"<beyond the top package>.{node.module or ''}"
    return ".".join(package[:keep] + ([node.module] if node.module else []))


def imported_modules(path: Path, root: Path = ROOT) -> set[str]:
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


def is_front_door(path: Path, root: Path = ROOT) -> bool:
    rel = path.relative_to(root / "suture_bt").as_posix()
    return any(rel == f or (f.endswith("/") and rel.startswith(f)) for f in FRONT_DOOR)


def restricted_files(root: Path = ROOT) -> list[Path]:
    files = [p for d in RESTRICTED_DIRS for p in (root / d).rglob("*.py")]
    files += [p for p in (root / "suture_bt").rglob("*.py") if not is_front_door(p, root)]
    return files


def forbidden_import(name: str) -> bool:
    return (
        name == "pybullet"
        or name.startswith(("pybullet.", "pybullet_"))
        or (name == "suture_bt.sim" or name.startswith("suture_bt.sim."))
    )


def import_offences(path: Path, root: Path = ROOT) -> list[str]:
    return sorted(n for n in imported_modules(path, root) if forbidden_import(n))


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


def source_offences(path: Path, root: Path = ROOT) -> list[str]:
    """Introspection and truth reads in one skills/behaviours/trees file, as 'line: what'."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found: list[str] = []

    def flag(node: ast.AST, what: str) -> None:
        found.append(f"{getattr(node, 'lineno', '?')}: {what}")

    for module in sorted(imported_modules(path, root)):
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
