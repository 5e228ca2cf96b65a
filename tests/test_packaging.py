"""The distribution installs every package under ``suture_bt`` and no top-level sim/skills."""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAPPED = {
    "sim": "suture_bt.sim",
    "skills": "suture_bt.skills",
    "behaviours": "suture_bt.behaviours",
    "trees": "suture_bt.trees",
    "suture_bt": "suture_bt",
}


def test_every_package_folder_is_listed_in_pyproject():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(conf["packages"])
    for top, dotted in MAPPED.items():
        for init in (ROOT / top).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / top).parts
            assert ".".join((dotted, *rel)) in listed, f"{init.parent} missing from pyproject"
    assert set(conf["package-dir"].values()) == set(MAPPED)


def test_subpackages_import_under_suture_bt():
    import suture_bt.behaviours
    import suture_bt.sim
    import suture_bt.skills
    import suture_bt.trees  # noqa: F401

    assert Path(suture_bt.__file__).parent.name == "suture_bt"
