"""Why there is no sequence (docs/motion_planner.md): the exact solvers' result and `qtree solve` say it in one line,
naming the action set it is a proof for (before: "no sequence: ...", a proof for no stated set of actions)."""
from __future__ import annotations

import json

import yaml

from qtree_task_planner.oracles import BlockingOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar, exact
from relocation_app.cli import main
from relocation_common.feasibility import FeasibilityAnswer, Label
from relocation_common.paths import resolve_scenario

IDS = ("o1", "o2", "o3", "T")


def problem() -> RelocationProblem:
    return RelocationProblem(IDS[:-1], {"o1": 0.2, "o2": 0.3, "o3": 0.4}, "T")


def test_a_blocking_cycle_is_named_by_both_solvers():
    oracle = BlockingOracle.from_relation({"T": ["o1"], "o1": ["T"]}, "T", IDS)
    for solve in (astar.solve, exact.solve):
        r = solve(problem(), oracle)
        assert not r.found
        assert "blocking cycle" in r.reason and "lane {o1}: o1 needs T moved" in r.reason, r.reason
        assert "\n" not in r.reason and r.to_dict()["reason"] == r.reason
    assert "never feasible: o1 (blocked)" in exact.solve(problem(), oracle).reason


class NoGrasp:
    """o2 and o3 reachable; o1 and T never (the planner's reason in the message); no lane information."""

    def feasibility(self, object_id, removed):
        if object_id in ("o1", "T"):
            return FeasibilityAnswer(Label.UNFEASIBLE, message=f"STPIK rejected the approach of {object_id}")
        return FeasibilityAnswer(Label.OBSTACLE)


def test_the_objects_no_grasp_reached_are_named_with_the_planners_reason():
    for solve in (astar.solve, exact.solve):
        r = solve(problem(), NoGrasp())
        assert r.reason.startswith("no sequence with the actions side_grasp, top_grasp: T unfeasible from every set "
                                   "reached"), r.reason
        assert "STPIK rejected the approach of T" in r.reason
    assert "never feasible: o1 (STPIK rejected the approach of o1)" in exact.solve(problem(), NoGrasp()).reason


def test_the_proof_names_the_action_set_of_the_problem():
    """The reason is a proof over the problem's actions (problem.RelocationProblem.action_set): said first, by both
    solvers, for the pick actions by default and for whatever set the problem states."""
    oracle = BlockingOracle.from_relation({"T": ["o1"], "o1": ["T"]}, "T", IDS)
    for solve in (astar.solve, exact.solve):
        assert solve(problem(), oracle).reason.startswith("no sequence with the actions side_grasp, top_grasp: ")
        only_side = RelocationProblem(IDS[:-1], {"o1": 0.2, "o2": 0.3, "o3": 0.4}, "T", action_set=("side_grasp",))
        assert solve(only_side, oracle).reason.startswith("no sequence with the action side_grasp: ")


def test_a_solved_problem_has_no_reason():
    r = astar.solve(problem(), BlockingOracle.from_relation({"T": ["o1"]}, "T", IDS))
    assert r.found and r.reason == "" and "reason" not in r.to_dict()


def test_qtree_solve_prints_the_reason(tmp_path, capsys):
    data = yaml.safe_load(resolve_scenario("blocking_5").read_text())
    data["blocking"] = {"T": ["o4"], "o4": ["T"]}
    path = tmp_path / "cycle.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["solve", "--scenario", str(path), "--json", str(tmp_path / "out.json")]) == 0
    err = capsys.readouterr().err
    assert "qtree: no sequence with the actions side_grasp, top_grasp: " in err and "blocking cycle" in err
    assert "blocking cycle" in json.loads((tmp_path / "out.json").read_text())["reason"]


def test_a_blocking_cycle_not_through_the_target_is_named():
    """T needs o1 moved, o1 needs o2, o2 needs o1: no lane of T can be cleared, though none needs T moved."""
    oracle = BlockingOracle.from_relation({"T": ["o1"], "o1": ["o2"], "o2": ["o1"]}, "T", IDS)
    for solve in (astar.solve, exact.solve):
        r = solve(problem(), oracle)
        assert not r.found
        assert "blocking cycle" in r.reason and "lane {o1}: o1 needs o2 moved; o2 needs o1 moved" in r.reason, r.reason
