"""The Q-Tree itself: Eq. 7 by hand on a three-node tree, Eq. 13 rewards, pruning, Eq. 15, best sequence, dot."""
import re

import pytest
from qtree_reference import reward, step

from qtree_task_planner.learning.q_tree import QTree
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import ProblemError, RelocationProblem
from relocation_common.feasibility import FeasibilityAnswer, Label

# a (phi 0.2) blocks the target T; b (phi 0.5) is free.
PROBLEM = RelocationProblem(("a", "b"), {"a": 0.2, "b": 0.5}, "T")
A, B, T = 0, 1, 2


def tree(alpha=0.5, gamma=0.9):
    return QTree(PROBLEM, BlockingOracle.from_relation({"T": ["a"]}, "T", ["a", "b", "T"]), alpha, gamma)


def test_reward_per_label_eq13():
    assert reward(Label.OBSTACLE, 0.37) == -0.37
    assert reward(Label.UNFEASIBLE, 0.37) == -10.0
    assert reward(Label.TARGET, 0.37) == 100.0


def test_eq7_on_a_three_node_tree_by_hand():
    t = tree(alpha=0.5, gamma=0.9)
    root = t.root
    # 1) target at the root: unfeasible, terminal: Q = 0 + 0.5 * (-10 - 0) = -5
    label, nxt = step(t, root, T)
    assert label == Label.UNFEASIBLE and nxt is None
    assert root.q_pruned[T] == pytest.approx(-5.0)
    # 2) relocate a: next node [a] has no edge yet, max = 0: Q = 0.5 * (-0.2 + 0.9 * 0) = -0.1
    label, node_a = step(t, root, A)
    assert label == Label.OBSTACLE and node_a.seq == (A,)
    assert root.q[A] == pytest.approx(-0.1)
    # 3) target from [a]: feasible, terminal: Q = 0.5 * 100 = 50
    label, nxt = step(t, node_a, T)
    assert label == Label.TARGET and nxt is None
    assert node_a.q[T] == pytest.approx(50.0)
    # 4) a again: Q = -0.1 + 0.5 * (-0.2 + 0.9 * 50 - (-0.1)) = 22.35
    step(t, root, A)
    assert root.q[A] == pytest.approx(22.35)
    # three nodes: s_H, [a] (the target state is terminal and needs no node), three edges, three queries
    assert len(t.nodes) == 2 and t.n_edges == 3 and t.mp_q == 3
    # Eq. 15: 5 + 22.35 + 50, incremental and from scratch
    assert t.q_sum == pytest.approx(77.35) and t.q_abs_sum() == pytest.approx(77.35)
    assert t.best_sequence() == ("a", "T")


def test_max_over_next_node_ignores_pruned_edges_and_is_zero_when_empty():
    t = tree(alpha=1.0, gamma=1.0)
    _, node_b = step(t, t.root, B)
    step(t, node_b, T)  # unfeasible at [b]: pruned there
    assert node_b.max_q() == 0.0 and node_b.q_pruned[T] == -10.0
    step(t, t.root, B)  # -0.5 + 1.0 * 0 (the pruned -10 does not count)
    assert t.root.q[B] == pytest.approx(-0.5)
    _, node_ba = step(t, node_b, A)
    step(t, node_ba, T)  # 100
    step(t, node_b, A)  # -0.2 + 100
    assert node_b.max_q() == pytest.approx(99.8)


def test_pruning_unfeasible_action_is_not_offered_again_at_that_node_only():
    t = tree()
    assert t.root.offered(3) == [A, B, T]
    step(t, t.root, T)
    assert t.root.offered(3) == [A, B]
    _, node_b = step(t, t.root, B)
    assert node_b.offered(3) == [A, T]  # b relocated in this sequence; T not yet tried here


def test_edges_ask_the_oracle_once_and_cache_by_set():
    cache = CachedOracle(BlockingOracle.from_relation({"T": ["a"]}, "T", ["a", "b", "T"]))
    t = QTree(PROBLEM, cache, 0.5, 0.9)
    _, na = step(t, t.root, A)
    _, nb = step(t, t.root, B)
    step(t, na, B)
    step(t, nb, A)  # {a} + b and {b} + a: two tree edges
    _, nab = step(t, na, B)  # known edge: no new query
    assert t.mp_q == 4 and cache.calls == 4
    step(t, nab, T)
    _, nba = step(t, nb, A)
    step(t, nba, T)  # same removed set {a, b} as before: a new edge (MP_q) but no real call
    assert t.mp_q == 6 and cache.calls == 5 and cache.queries == 6


def test_oracle_answering_target_for_an_obstacle_is_an_error():
    class Liar:
        def feasibility(self, object_id, removed):
            return FeasibilityAnswer(Label.TARGET)

    t = QTree(PROBLEM, Liar(), 0.5, 0.9)
    with pytest.raises(ValueError, match="TARGET is for the target only"):
        step(t, t.root, A)


def test_best_sequence_follows_highest_values_and_is_none_without_target():
    t = tree(alpha=1.0, gamma=1.0)
    assert t.best_sequence() is None
    _, na = step(t, t.root, A)
    assert t.best_sequence() is None  # [a] has no edge to the target yet
    _, nb = step(t, t.root, B)
    _, nba = step(t, nb, A)
    step(t, nba, T)
    step(t, nb, A)
    step(t, t.root, B)  # b, a, T: value 100 - 0.5 - 0.2
    assert t.best_sequence() == ("b", "a", "T")
    step(t, na, T)
    step(t, t.root, A)  # a, T: 100 - 0.2 beats 99.3
    assert t.best_sequence() == ("a", "T")


def test_dot_output_has_every_node_and_edge_with_styles():
    t = tree()
    step(t, t.root, T)
    _, na = step(t, t.root, A)
    step(t, na, T)
    step(t, t.root, B)
    dot = t.to_dot()
    assert dot.startswith("digraph q_tree {") and dot.rstrip().endswith("}")
    assert dot.count("{") == dot.count("}")
    edges = re.findall(r"^\s+(\w+) -> (\w+) \[(.*)\];$", dot, re.M)
    assert len(edges) == t.n_edges == 4
    by_label = {e[2].split("\\n")[0].split('"')[1]: e for e in edges if e[0] == "n0"}
    assert "color=red, style=dashed" in by_label["T"][2] and "Q=-5" in by_label["T"][2]
    assert "bold" in by_label["a"][2] and "bold" not in by_label["b"][2]  # best sequence a, T
    green = [e for e in edges if "color=green" in e[2]]
    assert len(green) == 1 and green[0][0] == f"n{na.id}" and "bold" in green[0][2]
    assert 'n0 [label="s_H"]' in dot and f'n{na.id} [label="a"]' in dot


def test_problem_validation():
    with pytest.raises(ProblemError, match="duplicate"):
        RelocationProblem(("a", "a"), {"a": 0.5}, "T")
    with pytest.raises(ProblemError, match=r"\(0, 1\]"):
        RelocationProblem(("a",), {"a": 1.5}, "T")
    with pytest.raises(ProblemError, match="no target"):
        RelocationProblem(("a",), {"a": 0.5}, "")
    assert PROBLEM.weight(("b", "a", "T")) == pytest.approx(0.7)
