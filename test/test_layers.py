"""The layer rule, read from the imports of every module (docs/architecture.md, "Layers").

1. relocation_common: imports nothing of the project but itself.
2. the four cores (qtree_task_planner, stpik_motion_planner, jaco2_sim_driver, perception_aruco): relocation_common
   and themselves (the one robot description, relocation_common.robot_description, serves the planner and the
   simulator alike), no exception.
3. relocation_app: anything.
Imports inside functions count too. And `__file__` locates files in one helper only (relocation_common/paths.py).
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
COMMON = "relocation_common"
CORES = ("qtree_task_planner", "stpik_motion_planner", "jaco2_sim_driver", "perception_aruco")
APP = "relocation_app"
PACKAGES = (COMMON, *CORES, APP)
EXCEPTIONS = {("jaco2_sim_driver", "relocation_common.robot_description")}


def project_imports(path: Path, root: Path):
    """(line, imported module) for every import of a project package in the file, relative ones resolved."""
    tree = ast.parse(path.read_text(), str(path))
    here = path.relative_to(root).with_suffix("").parts
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - node.level]
                mod = ".".join(base + ((node.module,) if node.module else ()))
                names = [f"{mod}.{a.name}" if not node.module else mod for a in node.names]
            else:
                names = [node.module or ""]
        else:
            continue
        for n in names:
            if n.split(".")[0] in PACKAGES:
                yield node.lineno, n


def allowed(package: str, imported: str) -> bool:
    top = imported.split(".")[0]
    return package == APP or top in (package, COMMON)


def violations(root: Path = ROOT) -> list[str]:
    out = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            for line, mod in project_imports(path, root):
                if not allowed(package, mod):
                    out.append(f"{path.relative_to(root)}:{line} imports {mod}")
    return out


def test_every_import_follows_the_layer_order():
    assert violations() == []


def test_the_check_catches_imports_against_the_order(tmp_path):
    (tmp_path / "stpik_motion_planner").mkdir()
    (tmp_path / "relocation_common").mkdir()
    bad = tmp_path / "stpik_motion_planner" / "probe.py"
    bad.write_text("def f():\n    from qtree_task_planner.params import TrainingParams\n")
    assert violations(tmp_path) == ["stpik_motion_planner/probe.py:2 imports qtree_task_planner.params"]
    bad.write_text("from ..relocation_app import demo\n")
    assert violations(tmp_path) == ["stpik_motion_planner/probe.py:1 imports relocation_app"]
    bad.write_text("from relocation_common.scenario import Scenario\nfrom . import rrt\n")
    (tmp_path / "relocation_common" / "probe.py").write_text("import stpik_motion_planner.rrt\n")
    assert violations(tmp_path) == ["relocation_common/probe.py:1 imports stpik_motion_planner.rrt"]


@pytest.mark.parametrize("package", PACKAGES)
def test_file_paths_come_from_one_helper(package):
    """Only relocation_common/paths.py turns __file__ into a path to config or data (the kernel's C source sits
    next to its module and is package data)."""
    users = [p.relative_to(ROOT).as_posix() for p in (ROOT / package).rglob("*.py") if "__file__" in p.read_text()]
    assert set(users) <= {"relocation_common/paths.py", "qtree_task_planner/kernel.py"}
