"""One source for every parameter of the motion planner: config/motion_planner.yaml (as
qtree_task_planner.learning.params.TrainingParams does). PlannerParams (with StpikParams, stpik.*, and PushParams,
push.*) and FollowerParams (follower.*) load from the file; every field has exactly one key there and every key
exactly one reader; no field carries a default of its own; no other dataclass field or function argument of
stpik_motion_planner keeps a second value of a key; and what is built without parameters uses the file's (a bare
`MotionPlanner(scenario)` planned with 3 approach yaws and no certification while the file said 5 and true)."""
import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from relocation_common.paths import config_file, default_scenario
from relocation_common.scenario import load_scenario
from stpik_motion_planner.execution import goal_check
from stpik_motion_planner.execution.follower import FollowerParams, TrajectoryFollower
from stpik_motion_planner.execution.streaming import StreamParams
from stpik_motion_planner.planning.params import PlannerParams, PushParams
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.stpik import StpikParams
from stpik_motion_planner.planning.trajectory import Trajectory

ROOT = Path(__file__).resolve().parent.parent
FILE, NODE = "motion_planner.yaml", "motion_planner"
# Settings the planner shares with the simulated driver (the arm interface, Table 7's joint speed limits): their one
# place is where both nodes read them, not this file's dataclasses; a default there is the robot's, not a copy.
SHARED = {"qdot_max", "finger_tolerance", "finger_stall_threshold", "finger_stall_interval", "command_interface",
          "driver_prefix"}


def _keys() -> list[str]:
    """The node section's keys as written, duplicates included (yaml.safe_load keeps the last)."""
    root = yaml.compose(config_file(FILE).read_text())
    node = next(v for k, v in root.value if k.value == NODE)
    params = next(v for k, v in node.value if k.value == "ros__parameters")
    return [k.value for k, _ in params.value]


def _values() -> dict:
    return yaml.safe_load(config_file(FILE).read_text())[NODE]["ros__parameters"]


def _has_default(f: dataclasses.Field) -> bool:
    return f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING


def _same(a, b) -> bool:
    """Equal values: numbers and number lists by value (a YAML list, a tuple, an array), the rest exactly."""
    if isinstance(a, (str, bool)) or isinstance(b, (str, bool)):
        return type(a) is type(b) and a == b
    return np.array_equal(np.asarray(a, float), np.asarray(b, float))


def test_every_key_is_given_once():
    keys = _keys()
    assert sorted(k for k in set(keys) if keys.count(k) > 1) == []


@pytest.mark.parametrize("klass,nested", [(PlannerParams, (StpikParams, PushParams)), (FollowerParams, ())])
def test_each_dataclass_loads_every_field_from_the_file_and_has_no_default(klass, nested):
    keys = set(_keys())
    fields = [f for f in dataclasses.fields(klass) if f.name not in ("stpik", "push")] + [
        f for n in nested for f in dataclasses.fields(n)]
    assert [f.name for f in fields if _has_default(f) and f.name not in SHARED] == [], "fields with a default"
    own = [k for k in klass.keys() if k.rsplit(".", 1)[-1] not in SHARED]
    assert sorted(set(own) - keys) == [], f"{klass.__name__} keys missing from config/{FILE}"
    loaded, values = klass.load(), _values()
    for k in own:
        obj = loaded.stpik if k.startswith("stpik.") else loaded.push if k.startswith("push.") else loaded
        assert _same(getattr(obj, k.rsplit(".", 1)[-1]), values[k]), k


def _node_reads() -> set[str]:
    """The keys the node shell reads itself: params["..."] in motion_planner_node.py."""
    tree = ast.parse((ROOT / "stpik_motion_planner" / "motion_planner_node.py").read_text())
    return {n.slice.value for n in ast.walk(tree) if isinstance(n, ast.Subscript) and isinstance(n.value, ast.Name)
            and n.value.id == "params" and isinstance(n.slice, ast.Constant) and isinstance(n.slice.value, str)}


def test_every_key_has_exactly_one_reader():
    readers = {"PlannerParams": set(PlannerParams.keys()), "FollowerParams": set(FollowerParams.keys()),
               "StreamParams": {f.name for f in dataclasses.fields(StreamParams)} - {"qdot_max", "follower"},
               "goal_check": set(goal_check.PARAMETERS), "motion_planner_node": _node_reads()}
    owners = {k: [r for r, ks in readers.items() if k in ks] for k in _keys()}
    assert {k: v for k, v in owners.items() if len(v) != 1} == {}


def _named_defaults(text: str, where: str, names: set[str]) -> list[str]:
    """Dataclass fields and function arguments named as a key (its last part) with a default other than None."""
    out = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ClassDef) and any("dataclass" in ast.unparse(d) for d in node.decorator_list):
            out += [f"{where}:{s.lineno} {node.name}.{s.target.id} = {ast.unparse(s.value)}" for s in node.body
                    if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name) and s.target.id in names
                    and s.value is not None and not (isinstance(s.value, ast.Constant) and s.value.value is None)]
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            args = a.posonlyargs + a.args
            pairs = list(zip(args[len(args) - len(a.defaults):], a.defaults)) + list(zip(a.kwonlyargs, a.kw_defaults))
            out += [f"{where}:{node.lineno} {node.name}({arg.arg}={ast.unparse(d)})" for arg, d in pairs
                    if d is not None and arg.arg in names and not (isinstance(d, ast.Constant) and d.value is None)]
    return out


def test_no_second_value_of_a_key_in_the_package():
    """A field or argument named as a key of the file has no default of its own (None, "the file's", is none)."""
    names = {k.rsplit(".", 1)[-1] for k in _keys()} - SHARED
    found = [x for p in sorted((ROOT / "stpik_motion_planner").rglob("*.py"))
             for x in _named_defaults(p.read_text(), p.relative_to(ROOT).as_posix(), names)]
    assert found == []


def test_the_scan_finds_a_second_value():
    text = ("@dataclass(frozen=True)\nclass P:\n    n_yaws: int = 3\n    max_yaw: float\n\n\n"
            "def f(x, max_yaw=0.35, seed=None, *, lift: float = 0.03):\n    pass\n")
    assert _named_defaults(text, "probe.py", {"n_yaws", "max_yaw", "seed", "lift"}) == [
        "probe.py:3 P.n_yaws = 3", "probe.py:7 f(max_yaw=0.35)", "probe.py:7 f(lift=0.03)"]
    assert _named_defaults("@dataclass\nclass Q:\n    clearance: float | None = None\n", "q.py", {"clearance"}) == []


def _flat(p: PlannerParams) -> dict:
    d = dataclasses.asdict(p)
    return {**{k: v for k, v in d.items() if k not in ("stpik", "push")},
            **{f"{n}.{k}": v for n in ("stpik", "push") for k, v in d[n].items()}}


def _same_params(a: PlannerParams, b: PlannerParams) -> bool:
    fa, fb = _flat(a), _flat(b)
    return fa.keys() == fb.keys() and all(_same(fa[k], fb[k]) for k in fa)


def test_what_is_built_without_parameters_uses_the_file():
    planner = MotionPlanner(load_scenario(default_scenario()))
    assert _same_params(planner.params, PlannerParams.load())
    assert (planner.params.n_yaws, planner.params.certify_relocation) == (_values()["n_yaws"],
                                                                        _values()["certify_relocation"])
    t = np.arange(3) * 0.01
    follower = TrajectoryFollower(Trajectory(t, np.zeros((3, 7)), np.zeros((3, 7))))
    assert follower.p == FollowerParams.load()
    assert goal_check.configured() == {k: float(_values()[k]) for k in goal_check.PARAMETERS}
