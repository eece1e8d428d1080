"""The layer rule, read from the imports of every module (docs/architecture.md, "Layers").

1. relocation_common: imports nothing of the project but itself.
2. the four cores (qtree_task_planner, stpik_motion_planner, jaco2_sim_driver, perception_aruco): relocation_common
   and themselves (the one robot description, relocation_common.robot_description, serves the planner and the
   simulator alike), no exception.
3. relocation_app: anything.
Imports inside functions count too. And `__file__` locates files in one helper only (relocation_common/paths.py).
Two more rules on the same reading: no import cycle among the project's modules (a cycle through a function-level
import is a cycle too), and no module uses another module's private (underscore) names: `from m import _f`,
`m._f` for an imported module m, or `obj._f` where `_f` is a function or method defined only in other modules.
Inside the two split cores each module sits in a room and imports only its own room and the rooms below it (ROOMS):
qtree_task_planner's problem/oracles at the bottom, learning/ and search/ beside each other (neither imports the
other), executive/ above both, then ros_clients and markers, then the node; stpik_motion_planner's model/, planning/,
execution/, then service, ros_interface and the node. A module outside every room fails too. And no folder of the
project's packages holds more than MAX_MODULES modules (.py files other than __init__.py).
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
COMMON = "relocation_common"
CORES = ("qtree_task_planner", "stpik_motion_planner", "jaco2_sim_driver", "perception_aruco")
APP = "relocation_app"
PACKAGES = (COMMON, *CORES, APP)


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
    bad.write_text("def f():\n    from qtree_task_planner.learning.params import TrainingParams\n")
    assert violations(tmp_path) == ["stpik_motion_planner/probe.py:2 imports qtree_task_planner.learning.params"]
    bad.write_text("from ..relocation_app import demo\n")
    assert violations(tmp_path) == ["stpik_motion_planner/probe.py:1 imports relocation_app"]
    bad.write_text("from relocation_common.scenario import Scenario\nfrom . import rrt\n")
    (tmp_path / "relocation_common" / "probe.py").write_text("import stpik_motion_planner.planning.rrt\n")
    assert violations(tmp_path) == ["relocation_common/probe.py:1 imports stpik_motion_planner.planning.rrt"]


@pytest.mark.parametrize("package", PACKAGES)
def test_file_paths_come_from_one_helper(package):
    """Only relocation_common/paths.py turns __file__ into a path to config or data (the kernel's C source sits
    next to its module and is package data)."""
    users = [p.relative_to(ROOT).as_posix() for p in (ROOT / package).rglob("*.py") if "__file__" in p.read_text()]
    assert set(users) <= {"relocation_common/paths.py", "qtree_task_planner/learning/kernel.py"}


# ---------------------------------------------------------------------------------------------------------- cycles
def module_names(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the project's packages: dotted name -> file (a package is its __init__.py)."""
    out = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(path: Path, root: Path, modules: dict[str, Path]):
    """(line, imported module, {local name: module or None for a name that is not a module}) of every project
    import in the file, functions included; `from m import n` counts as an import of m.n when that is a module."""
    tree = ast.parse(path.read_text(), str(path))
    parts = path.relative_to(root).with_suffix("").parts
    package = parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PACKAGES:
                    yield node.lineno, a.name, {(a.asname or a.name.split(".")[0]): a.name if a.asname else None}
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(package[:len(package) - node.level + 1] + ((node.module,) if node.module else ())) \
                if node.level else (node.module or "")
            if base.split(".")[0] not in PACKAGES:
                continue
            for a in node.names:
                sub = f"{base}.{a.name}"
                yield node.lineno, (sub if sub in modules else base), {a.asname or a.name: sub if sub in modules
                                                                       else None}


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """module -> the project modules it imports."""
    modules = module_names(root)
    return {m: {imp for _, imp, _ in _imports(p, root, modules) if imp in modules and imp != m}
            for m, p in modules.items()}


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def test_no_import_cycle_among_the_modules():
    assert import_cycles(import_graph()) == []


def test_the_cycle_check_finds_a_cycle_through_a_function_level_import(tmp_path):
    (tmp_path / "relocation_app").mkdir()
    (tmp_path / "relocation_app" / "__init__.py").write_text("")
    (tmp_path / "relocation_app" / "a.py").write_text("from .b import g\n")
    (tmp_path / "relocation_app" / "b.py").write_text("def g():\n    from relocation_app import a\n")
    (tmp_path / "relocation_app" / "c.py").write_text("from . import a\n")
    assert import_cycles(import_graph(tmp_path)) == [["relocation_app.a", "relocation_app.b"]]


# ------------------------------------------------------------------------------------------------- private names
def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_uses(root: Path = ROOT) -> list[str]:
    """Where a module uses another module's private name (see the module docstring for the three forms)."""
    modules = module_names(root)
    trees = {m: ast.parse(p.read_text(), str(p)) for m, p in modules.items()}
    defined = {m: {n.name for n in ast.walk(t) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
               for m, t in trees.items()}
    elsewhere: dict[str, set[str]] = {}
    for m, names in defined.items():
        for n in names:
            elsewhere.setdefault(n, set()).add(m)
    out = []
    for m, path in modules.items():
        where = path.relative_to(root)
        aliases = {}
        for line, imp, names in _imports(path, root, modules):
            for local, module in names.items():
                if module is None and _private(local) and imp != m:
                    out.append(f"{where}:{line} imports {imp}.{local}")
                elif module is not None:
                    aliases[local] = module
        for node in ast.walk(trees[m]):
            if not isinstance(node, ast.Attribute) or not _private(node.attr):
                continue
            owner = node.value
            if isinstance(owner, ast.Name) and owner.id in aliases and aliases[owner.id] != m:
                out.append(f"{where}:{node.lineno} uses {aliases[owner.id]}.{node.attr}")
            elif node.attr in elsewhere and node.attr not in defined[m] and not (
                    isinstance(owner, ast.Name) and owner.id in ("self", "cls")):
                out.append(f"{where}:{node.lineno} calls {node.attr} of {', '.join(sorted(elsewhere[node.attr]))}")
    return out


def test_no_module_uses_another_modules_private_names():
    assert private_uses() == []


def test_the_private_check_finds_each_form(tmp_path):
    (tmp_path / "stpik_motion_planner").mkdir()
    pkg = tmp_path / "stpik_motion_planner"
    (pkg / "a.py").write_text("def _f():\n    pass\n\n\nclass P:\n    def _clear(self):\n        pass\n")
    (pkg / "b.py").write_text("from .a import _f\nfrom . import a\n\n\ndef g(p):\n    a._f()\n"
                              "    return p._clear()\n")
    assert private_uses(tmp_path) == ["stpik_motion_planner/b.py:1 imports stpik_motion_planner.a._f",
                                      "stpik_motion_planner/b.py:6 uses stpik_motion_planner.a._f",
                                      "stpik_motion_planner/b.py:7 calls _clear of stpik_motion_planner.a"]


# ------------------------------------------------------------------------------------------------ rooms of a core
# package -> its rooms from the bottom up, each (rank, the first names below the package it holds: modules or
# folders; "" is the package's own __init__). A module imports its own room and the rooms of a lower rank; rooms of
# one rank do not import each other.
ROOMS = {
    "qtree_task_planner": ((0, {"", "problem", "oracles"}), (1, {"learning"}), (1, {"search"}), (2, {"executive"}),
                           (3, {"ros_clients"}), (3, {"markers"}), (4, {"task_planner_node"})),
    "stpik_motion_planner": ((0, {"", "model"}), (1, {"planning"}), (2, {"execution"}), (3, {"service"}),
                             (4, {"ros_interface"}), (5, {"motion_planner_node"})),
}


def _room(module: str) -> tuple[str, int | None]:
    """(package, index of its room in ROOMS[package] or None) of a dotted module name."""
    parts = module.split(".")
    first = parts[1] if len(parts) > 1 else ""
    rooms = ROOMS.get(parts[0], ())
    return parts[0], next((i for i, (_, names) in enumerate(rooms) if first in names), None)


def room_violations(root: Path = ROOT) -> list[str]:
    """Imports inside a split core (functions included) that go up or sideways between rooms of one rank, and the
    modules that are in no room."""
    modules = module_names(root)
    out = []
    for m, path in modules.items():
        package, room = _room(m)
        if package not in ROOMS:
            continue
        where = path.relative_to(root)
        if room is None:
            out.append(f"{where} is in no room of {package}")
            continue
        rank = ROOMS[package][room][0]
        for line, imp, _ in _imports(path, root, modules):
            imp_package, imp_room = _room(imp)
            if imp_package == package and imp_room != room and (
                    imp_room is None or ROOMS[package][imp_room][0] >= rank):
                out.append(f"{where}:{line} imports {imp}")
    return out


def test_every_import_inside_a_split_core_goes_down():
    assert room_violations() == []


def test_the_room_check_catches_each_wrong_direction(tmp_path):
    q = tmp_path / "qtree_task_planner"
    for folder in ("learning", "search", "executive"):
        (q / folder).mkdir(parents=True)
    (q / "problem.py").write_text("")
    (q / "oracles.py").write_text("from .problem import Problem\n")
    (q / "search" / "exact.py").write_text("from ..oracles import Oracle\n")
    (q / "executive" / "retrieval.py").write_text("from ..search import exact\nfrom ..learning import q_tree\n")
    (q / "task_planner_node.py").write_text("from .executive import retrieval\n")
    (q / "learning" / "q_tree.py").write_text("from qtree_task_planner.problem import Problem\n")
    assert room_violations(tmp_path) == []
    (q / "learning" / "q_tree.py").write_text("def f():\n    from qtree_task_planner.search import exact\n")
    (q / "search" / "exact.py").write_text("from ..executive.retrieval import retrieve\n")
    (q / "problem.py").write_text("from . import task_planner_node\n")
    (q / "stray.py").write_text("")
    assert room_violations(tmp_path) == [
        "qtree_task_planner/learning/q_tree.py:2 imports qtree_task_planner.search.exact",
        "qtree_task_planner/problem.py:1 imports qtree_task_planner.task_planner_node",
        "qtree_task_planner/search/exact.py:1 imports qtree_task_planner.executive.retrieval",
        "qtree_task_planner/stray.py is in no room of qtree_task_planner"]
    s = tmp_path / "stpik_motion_planner"
    (s / "model").mkdir(parents=True)
    (s / "planning").mkdir()
    (s / "model" / "grasp.py").write_text("from stpik_motion_planner.planning import rrt\n")
    (s / "planning" / "rrt.py").write_text("from ..model import grasp\nfrom .. import service\n")
    (s / "service.py").write_text("from . import ros_interface\n")
    (s / "ros_interface.py").write_text("from .service import serve\n")
    assert [v for v in room_violations(tmp_path) if v.startswith("stpik")] == [
        "stpik_motion_planner/model/grasp.py:1 imports stpik_motion_planner.planning.rrt",
        "stpik_motion_planner/planning/rrt.py:2 imports stpik_motion_planner.service",
        "stpik_motion_planner/service.py:1 imports stpik_motion_planner.ros_interface"]


# ---------------------------------------------------------------------------------------------- modules per folder
MAX_MODULES = 12  # "no folder holds more than about a dozen modules"


def crowded_folders(root: Path = ROOT, most: int = MAX_MODULES) -> dict[str, int]:
    """Folder -> its number of modules (.py files other than __init__.py), for folders holding more than `most`."""
    counts: dict[str, int] = {}
    for package in PACKAGES:
        for path in (root / package).rglob("*.py"):
            if path.name != "__init__.py":
                folder = path.parent.relative_to(root).as_posix()
                counts[folder] = counts.get(folder, 0) + 1
    return {f: n for f, n in sorted(counts.items()) if n > most}


def test_no_folder_holds_more_than_a_dozen_modules():
    assert crowded_folders() == {}


def test_the_folder_count_catches_a_crowded_folder(tmp_path):
    folder = tmp_path / "relocation_app" / "evaluation"
    folder.mkdir(parents=True)
    for i in range(MAX_MODULES):
        (folder / f"m{i}.py").write_text("")
    (folder / "__init__.py").write_text("")
    assert crowded_folders(tmp_path) == {}
    (folder / "one_more.py").write_text("")
    assert crowded_folders(tmp_path) == {"relocation_app/evaluation": MAX_MODULES + 1}
