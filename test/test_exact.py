"""Exact minimum-weight sequence: lazy uniform-cost search vs brute force (hypothesis), and the shipped
blocking scenarios whose optimum is known by hand."""
import hashlib
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search.exact import brute_force, solve
from relocation_common.feasibility import FeasibilityAnswer, Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import ScenarioError, load_scenario


@pytest.mark.parametrize("n, sequence, weight", [
    (5, ("o1", "o4", "T"), 0.76), (10, ("o3", "o6", "T"), 1.01), (15, ("o3", "o8", "o13", "T"), 1.09)])
def test_shipped_blocking_scenarios(n, sequence, weight):
    sc = load_scenario(scenarios_dir() / f"blocking_{n}.yaml")
    oracle = BlockingOracle(sc)
    r = solve(sc, oracle)
    assert r.sequence == sequence and r.total_weight == pytest.approx(weight)
    b = brute_force(sc, oracle)
    assert b.total_weight == pytest.approx(weight) and b.oracle_calls > r.oracle_calls


def test_blocking_oracle_answers_and_errors():
    o = BlockingOracle.from_relation({"T": ["a", "b"], "b": ["a"]}, "T", ["a", "b", "c", "T"])
    assert o.feasibility("a", frozenset()).label == Label.OBSTACLE
    assert o.feasibility("b", frozenset()).label == Label.UNFEASIBLE
    assert o.feasibility("T", frozenset({"a"})).label == Label.UNFEASIBLE
    assert o.feasibility("T", frozenset({"a", "b"})).label == Label.TARGET
    with pytest.raises(KeyError):
        o.feasibility("zz", frozenset())
    with pytest.raises(ValueError, match="already removed"):
        o.feasibility("a", frozenset({"a"}))
    with pytest.raises(ValueError, match="unknown ids"):
        BlockingOracle.from_relation({"T": ["x"]}, "T", ["a", "T"])
    with pytest.raises(ScenarioError, match="no 'blocking:' section"):
        BlockingOracle(load_scenario(scenarios_dir() / "paper_experiment_10.yaml"))


def test_no_feasible_sequence():
    p = RelocationProblem(("a", "b"), {"a": 0.5, "b": 0.5}, "T")
    o = BlockingOracle.from_relation({"T": ["a"], "a": ["b"], "b": ["a"]}, "T", ["a", "b", "T"])
    assert not solve(p, o).found and not brute_force(p, o).found


class TableOracle:
    """An arbitrary feasibility function (not monotone, unlike a blocking relation), fixed by a seed."""

    def __init__(self, seed, target, p_feasible):
        self.seed, self.target, self.p = seed, target, p_feasible
        self.asked = []

    def feasibility(self, object_id, removed):
        self.asked.append((object_id, frozenset(removed)))
        key = f"{self.seed}|{object_id}|{','.join(sorted(removed))}".encode()
        u = int.from_bytes(hashlib.blake2b(key, digest_size=8).digest(), "big") / 2**64
        if u >= self.p:
            return FeasibilityAnswer(Label.UNFEASIBLE)
        return FeasibilityAnswer(Label.TARGET if object_id == self.target else Label.OBSTACLE)


def instance(seed, n, kind, p):
    rnd = random.Random(seed)
    obstacles = tuple(f"o{i}" for i in range(n))
    weights = {o: rnd.choice([0.05, 0.1, 0.25, 0.3, 0.5, 0.7, 1.0]) for o in obstacles}
    problem = RelocationProblem(obstacles, weights, "T")
    if kind == "table":
        return problem, TableOracle(seed, "T", p)
    ids = obstacles + ("T",)
    blocking = {o: rnd.sample([x for x in ids if x != o], rnd.randint(0, min(3, n))) for o in ids}
    return problem, BlockingOracle.from_relation(blocking, "T", ids)


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 10**9), n=st.integers(0, 8), kind=st.sampled_from(["table", "blocking"]),
       p=st.floats(0.2, 0.9))
def test_lazy_ucs_matches_brute_force(seed, n, kind, p):
    problem, oracle = instance(seed, n, kind, p)
    exact = solve(problem, oracle)
    asked = list(getattr(oracle, "asked", []))
    ref = brute_force(problem, oracle)
    assert exact.found == ref.found
    if ref.found:
        assert exact.total_weight == pytest.approx(ref.total_weight, abs=1e-9)
        # the returned sequence is feasible step by step and weighs what it says
        removed = frozenset()
        for o in exact.sequence[:-1]:
            assert oracle.feasibility(o, removed).label == Label.OBSTACLE
            removed |= {o}
        assert oracle.feasibility("T", removed).label == Label.TARGET
        assert exact.total_weight == pytest.approx(problem.weight(exact.sequence))
    if asked:  # lazy search: each (object, set) is asked at most once
        assert len(asked) == len(set(asked)) == exact.oracle_calls


def test_solve_counts_calls_behind_a_cache():
    sc = load_scenario(scenarios_dir() / "blocking_15.yaml")
    cache = CachedOracle(BlockingOracle(sc))
    r = solve(sc, cache)
    assert cache.calls == r.oracle_calls == cache.queries
