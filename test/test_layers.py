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
