"""One action model for both planners (qtree_task_planner.problem, "One action model"; docs/qtree.md): relocating
obstacle i costs phi_i x the factor of its action (config/task_planner.yaml `action_cost`), the pick's action known
from the object's pose. A factor changes the optimum: the A*, the uniform-cost reference, brute force and the trained
Q-Tree all find the cheaper sequence, and the results keep Eq. 8's weight with the cost beside it. Before, every
relocation cost its weight whatever the action, and the lying bottle's top grasp was as cheap as a side grasp."""
from __future__ import annotations

import pytest

from qtree_task_planner.learning.checkpoint import problem_hash
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.problem import MAX_FACTOR, ActionCosts, ProblemError, RelocationProblem
from qtree_task_planner.search import astar, exact
from relocation_common.config import ParameterError
from relocation_common.feasibility import ACTIONS, TOP_GRASP, BlockerSet, FeasibilityAnswer, Label
from relocation_common.scenario import ShelfObject

FACTORS = ActionCosts(side_grasp=1.0, top_grasp=1.5, push=2.0)  # the test's own, not the shipped file's
PAPER = ActionCosts(side_grasp=1.0, top_grasp=1.0, push=1.0)
WEIGHTS = {"a": 0.3, "b": 0.2, "c": 0.2, "d": 0.9}


class TwoLanes:
    """T has two grasp lanes: one behind a (a lying bottle), one behind b and c (standing); d stands aside (never
    needed). Every obstacle is reachable."""

    lanes = (frozenset({"a"}), frozenset({"b", "c"}))

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        if object_id != "T":
            return FeasibilityAnswer(Label.OBSTACLE, action=TOP_GRASP if object_id == "a" else "side_grasp")
        if any(lane <= removed for lane in self.lanes):
            return FeasibilityAnswer(Label.TARGET, action="side_grasp")
        return FeasibilityAnswer(Label.UNFEASIBLE, message="blocked",
                                 blockers=tuple(BlockerSet(lane - removed) for lane in self.lanes))


def problem(costs: ActionCosts) -> RelocationProblem:
    return RelocationProblem(tuple(WEIGHTS), WEIGHTS, "T").with_actions({"a": TOP_GRASP}, costs)


PARAMS = TrainingParams.defaults().replace(seed=0, max_episodes=3000)


@pytest.mark.parametrize("costs, best, weight, cost", [
    (PAPER, {("a", "T")}, 0.3, None),  # the paper's: a (0.3) is lighter than b + c (0.4); no cost reported
    (FACTORS, {("b", "c", "T"), ("c", "b", "T")}, 0.4, 0.4),  # a from above costs 0.45: b and c are cheaper
])
def test_a_cost_factor_changes_the_optimum_and_every_solver_agrees(costs, best, weight, cost):
    p = problem(costs)
    results = [solve(p, TwoLanes()) for solve in (astar.solve, exact.solve, exact.brute_force)]
    for r in results:
        assert r.sequence in best and r.total_weight == pytest.approx(weight) and r.total_cost == pytest.approx(cost)
        assert ("total_cost" in r.to_dict()) == (cost is not None)
    opt = results[0]
    learned = train(p, TwoLanes(), PARAMS, optimal_weight=opt.total_weight, optimal_cost=opt.total_cost)
    assert learned.sequence in best and learned.total_cost == pytest.approx(cost), learned.sequence
    assert learned.total_weight == pytest.approx(weight)
    assert learned.e_1st is not None  # the greedy path reached the optimum's cost during training


def test_results_keep_eq_8_s_weight_and_add_the_cost_of_a_costed_problem():
    """a taken alone: weight 0.3, cost 0.45 (FACTORS); the paper's problem reports no cost."""
    p = problem(FACTORS)
    only_a = RelocationProblem(("a",), {"a": 0.3}, "T").with_actions({"a": TOP_GRASP}, FACTORS)
    r = astar.solve(only_a, TwoLanes())
    assert r.sequence == ("a", "T") and r.to_dict()["total_weight"] == pytest.approx(0.3)
    assert r.to_dict()["total_cost"] == pytest.approx(0.45)
    assert "total_cost" not in astar.solve(problem(PAPER), TwoLanes()).to_dict()  # the paper's results unchanged
    trained = train(only_a, TwoLanes(), PARAMS.replace(max_episodes=200), optimal_weight=0.3, optimal_cost=0.45)
    assert trained.to_dict()["total_cost"] == pytest.approx(0.45) and trained.to_dict()["total_weight"] == 0.3
    assert p.costed and not problem(PAPER).costed
    assert "a 0.30 x 1.50 = 0.45" in p.costs_line() and problem(PAPER).costs_line() == ""
    with pytest.raises(ValueError, match="optimal_cost"):  # E_1st against the weight of a costed problem: refused
        train(p, TwoLanes(), PARAMS, optimal_weight=0.4)


def test_a_costed_problem_is_another_checkpoint_problem_and_the_paper_s_keeps_its_hash():
    plain = RelocationProblem(tuple(WEIGHTS), WEIGHTS, "T")
    assert problem_hash(problem(PAPER)) == problem_hash(plain)
    assert problem_hash(problem(FACTORS)) != problem_hash(plain)


def test_the_pick_s_action_follows_from_the_pose():
    standing = ShelfObject("s", "red", (1, 0, 0), 0.4, 0.7, 0.0, 0.033, 0.16, False)
    lying = ShelfObject("l", "red", (1, 0, 0), 0.4, 0.7, 0.1, 0.033, 0.16, False, lying=True)
    target = ShelfObject("T", "red", (1, 0, 0), 1.0, 0.8, 0.0, 0.033, 0.16, True)
    p = RelocationProblem.from_bottles((standing, lying, target), FACTORS)
    assert p.costs == {"s": pytest.approx(0.4), "l": pytest.approx(0.6)} and p.weights == {"s": 0.4, "l": 0.4}
    assert RelocationProblem.from_bottles((standing, lying, target)).costs == {"s": 0.4, "l": 0.4}


def test_the_factors_come_from_the_shipped_file_and_bad_ones_are_refused():
    shipped = ActionCosts.from_yaml()
    assert shipped.side_grasp == 1.0  # the paper's numbers unchanged
    assert set(shipped.to_dict()) == set(ACTIONS)
    for bad in (0.0, -1.0, MAX_FACTOR + 1, float("nan"), True, "1"):
        with pytest.raises(ParameterError, match="action_cost.top_grasp"):
            ActionCosts(side_grasp=1.0, top_grasp=bad, push=1.0)
    with pytest.raises(ParameterError, match="unknown kind.*pull.*missing push"):
        ActionCosts.from_mapping({"side_grasp": 1.0, "top_grasp": 1.0, "pull": 1.0})
    with pytest.raises(ProblemError, match="cost of 'a'"):
        RelocationProblem(("a",), {"a": 0.3}, "T", costs={"a": 0.0})
    with pytest.raises(ProblemError, match="action_set"):
        RelocationProblem(("a",), {"a": 0.3}, "T", action_set=("fly",))


def test_a_re_plan_costs_a_bottle_lying_on_the_shelf_as_a_top_grasp():
    """world.remaining_problem with the factors: headroom_lying_6's o1 lies (perceived tilted), so the re-plan's
    A* costs it as a grasp from above; without them (the paper's problem) it costs its weight."""
    from qtree_task_planner.executive.world import remaining_problem, scene_of, seen_object
    from relocation_common.scenario import load_scenario

    sc = load_scenario("config/scenarios/headroom_lying_6.yaml")
    scene = scene_of(seen_object(o) for o in sc.objects)  # as perception sees them: o1 lying
    rp = remaining_problem(sc, scene, (), action_cost=FACTORS)
    assert rp.tipped == ("o1",) and rp.problem is not None
    assert rp.problem.costs["o1"] == pytest.approx(0.30 * 1.5) and rp.problem.costs["o2"] == pytest.approx(0.25)
    plain = remaining_problem(sc, scene, ()).problem
    assert plain is not None and not plain.costed
