"""The honesty boundary (DESIGN.md §3): who may import pybullet, the simulator and ground truth.

Parsed with ``ast`` (imports inside functions count too). Skills, behaviours, trees and the
core (``suture_bt/`` except the front-door modules below) must not import pybullet or
``suture_bt.sim``; ``suture_bt.sim.ground_truth`` may be imported only by front-door modules,
tests and benchmarks (and by nothing in ``sim/`` other than itself).
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Front-door modules of the core (paths relative to suture_bt/): they wire worlds to trees.
FRONT_DOOR = ("cli.py", "commands/", "runtime/", "evaluation/", "oracle/", "datagen/")
RESTRICTED_DIRS = ("skills", "behaviours", "trees")


def _imports(path: Path) -> set[str]:
    """Absolute module names a file imports (``from a.b import c`` gives a.b and a.b.c)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import: resolve against the file's package
                rel = path.relative_to(ROOT).with_suffix("").parts[: -node.level]
                base = ".".join(_package_parts(rel) + ([base] if base else []))
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def _package_parts(parts: tuple[str, ...]) -> list[str]:
    mapping = {"sim": "suture_bt.sim", "skills": "suture_bt.skills"}
    mapping |= {"behaviours": "suture_bt.behaviours", "trees": "suture_bt.trees"}
    if parts and parts[0] in mapping:
        return [mapping[parts[0]], *parts[1:]]
    return list(parts)


def _is_front_door(path: Path) -> bool:
    rel = path.relative_to(ROOT / "suture_bt").as_posix()
    return any(rel == f or (f.endswith("/") and rel.startswith(f)) for f in FRONT_DOOR)


def _restricted_files() -> list[Path]:
    files = [p for d in RESTRICTED_DIRS for p in (ROOT / d).rglob("*.py")]
    files += [p for p in (ROOT / "suture_bt").rglob("*.py") if not _is_front_door(p)]
    return files


def _forbidden(name: str) -> bool:
    return (
        name == "pybullet"
        or name.startswith(("pybullet.", "pybullet_"))
        or (name == "suture_bt.sim" or name.startswith("suture_bt.sim."))
    )


def test_core_skills_behaviours_trees_do_not_import_the_simulator():
    offenders = []
    for path in _restricted_files():
        bad = sorted(n for n in _imports(path) if _forbidden(n))
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
