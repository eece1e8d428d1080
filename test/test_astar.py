"""Blocker A* (qtree_task_planner.search.astar) against brute force and uniform-cost search (hypothesis), on random
instances whose objects have several grasp lanes (an object is reachable once all objects of one of its lanes are
removed), with blockers reported exactly, only as answers, as subsets, partly uncertain, or not at all, and with
failures no blocker explains (as STPIK's)."""
import hashlib
import math
import random
from functools import lru_cache

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar, exact
from qtree_task_planner.search.reachable import reachable_sets
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

MODES = ("exact", "answers", "subset", "uncertain", "none")


def _rng(*key) -> random.Random:
    return random.Random(hashlib.blake2b("|".join(map(str, key)).encode(), digest_size=8).digest())


class LaneOracle:
    """Truth: lanes[o] (alternative sets), plus failures with probability p_fail that no blocker explains.
    Reports blockers by `mode` (all of them true claims or marked uncertain)."""

    def __init__(self, seed, lanes, target, mode, p_fail):
        self.seed, self.lanes, self.target, self.mode, self.p_fail = seed, lanes, target, mode, p_fail
        self.asked = []

    def truly(self, o, removed):
        clear = any(b <= removed for b in self.lanes[o])
        return clear and _rng(self.seed, "fail", o, sorted(removed)).random() >= self.p_fail

    def _report(self, o, removed, rnd):
        out = []
        others = sorted(set(self.lanes) - {o} - removed)
        for b in self.lanes[o]:
            left = b - removed
            if not left or (self.mode == "uncertain" and rnd.random() < 0.4):  # cleared but failed / a suspicion
                out.append(BlockerSet(rnd.sample(others, min(len(others), rnd.randint(0, 2))), certain=False))
            elif self.mode == "subset":  # a true lane's subset claims less: still sound
                out.append(BlockerSet(rnd.sample(sorted(left), rnd.randint(0, len(left)))))
            else:
                out.append(BlockerSet(left))
        if self.mode == "uncertain" and out and rnd.random() < 0.3:  # a lane left out: no longer a claim
            out[rnd.randrange(len(out))] = BlockerSet((), certain=False)
        return tuple(out)

    def feasibility(self, o, removed):
        removed = frozenset(removed)
        self.asked.append((o, removed))
        if self.truly(o, removed):
            return FeasibilityAnswer(Label.TARGET if o == self.target else Label.OBSTACLE)
        blockers = () if self.mode == "none" else self._report(o, removed, _rng(self.seed, "ans", o, sorted(removed)))
        return FeasibilityAnswer(Label.UNFEASIBLE, blockers=blockers)

    def lane_blockers(self, removed):
        if self.mode in ("answers", "none"):
            return None
        return {o: self._report(o, removed, _rng(self.seed, "lanes", o)) for o in self.lanes if o not in removed}


def lane_instance(seed, n, mode, p_fail):
    rnd = random.Random(seed)
    obstacles = tuple(f"o{i}" for i in range(n))
    problem = RelocationProblem(obstacles, {o: rnd.choice([0.05, 0.1, 0.25, 0.3, 0.5, 0.7, 1.0]) for o in obstacles},
                                "T")
    ids = obstacles + ("T",)
    lanes = {}
    for o in ids:  # the target: mostly one or two lanes of obstacles; some objects with none (never reachable)
        pop = [x for x in obstacles if x != o]
        lanes[o] = [frozenset(rnd.sample(pop, rnd.randint(min(o == "T", len(pop)), min(3, len(pop)))))
                    for _ in range(rnd.choice([0, 1, 1, 1, 2, 2, 3] if o == "T" else [0, 1, 1, 2, 3]))]
    return problem, LaneOracle(seed, lanes, "T", mode, p_fail)


def check_sequence(problem, oracle, result):
    removed = frozenset()
    for o in result.sequence[:-1]:
        assert oracle.truly(o, removed)
        removed |= {o}
    assert result.sequence[-1] == problem.target and oracle.truly(problem.target, removed)
    assert result.total_weight == pytest.approx(problem.weight(result.sequence))


@settings(max_examples=400, deadline=None)
@given(seed=st.integers(0, 10**9), n=st.integers(0, 7), mode=st.sampled_from(MODES),
       p_fail=st.sampled_from([0.0, 0.0, 0.15, 0.4]))
def test_astar_matches_brute_force(seed, n, mode, p_fail):
    problem, oracle = lane_instance(seed, n, mode, p_fail)
    r = astar.solve(problem, oracle)
    asked = list(oracle.asked)
    assert len(asked) == len(set(asked)) == r.oracle_calls  # each (object, set) at most once
    ref = brute_force_weight(problem, oracle)
    assert r.found == (ref is not None)
    if r.found:
        assert r.total_weight == pytest.approx(ref, abs=1e-9)
        check_sequence(problem, oracle, r)
    if mode == "exact" and p_fail == 0.0:  # complete, exact blockers: the first path is the answer
        assert r.oracle_calls == (len(r.sequence) if r.found else 0) and r.searches == 1


def brute_force_weight(problem, oracle):
    ref = exact.brute_force(problem, oracle)
    oracle.asked.clear()
    return ref.total_weight


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 10**9), n=st.integers(1, 7), mode=st.sampled_from(("exact", "subset", "uncertain")))
def test_heuristic_never_exceeds_the_true_cost_to_go(seed, n, mode):
    """h(R) <= the least weight still to remove from R before the target is feasible, on every reachable R."""
    problem, oracle = lane_instance(seed, n, mode, 0.0)
    kb = astar.Knowledge(problem.weights, "T")
    for o, sets in oracle.lane_blockers(frozenset()).items():
        kb.lanes_known(o, frozenset(), sets)
    for o in problem.ids:  # and some answers' claims
        kb.record(o, frozenset(), oracle.feasibility(o, frozenset()))

    @lru_cache(maxsize=None)
    def to_go(removed):
        if oracle.truly("T", removed):
            return 0.0
        return min((problem.weights[o] + to_go(removed | {o}) for o in problem.obstacles
                    if o not in removed and oracle.truly(o, removed)), default=math.inf)

    reach = reachable_sets(problem.obstacles, oracle.truly)
    for removed in reach:
        assert kb.h(removed) <= to_go(removed) + 1e-9


def test_uncertain_blockers_claim_nothing():
    kb = astar.Knowledge({"a": 0.5, "b": 0.7}, "T")
    kb.record("T", frozenset(), FeasibilityAnswer(Label.UNFEASIBLE, blockers=(
        BlockerSet({"a"}), BlockerSet({"a", "b"}, certain=False))))
    assert kb.h(frozenset()) == 0.0 and kb.possible("T", frozenset({"b"}))
    kb.record("T", frozenset({"b"}), FeasibilityAnswer(Label.UNFEASIBLE, blockers=(BlockerSet({"a"}),)))
    assert kb.h(frozenset()) == 0.0  # a claim made at {b} says nothing about sets without b
    assert kb.h(frozenset({"b"})) == 0.5 and not kb.possible("T", frozenset({"b"}))
    kb.lanes_known("a", frozenset(), ())  # a can never be relocated
    assert kb.h(frozenset({"b"})) == math.inf


@pytest.mark.parametrize("n, sequence, weight", [
    (5, ("o1", "o4", "T"), 0.76), (10, ("o3", "o6", "T"), 1.01), (15, ("o3", "o8", "o13", "T"), 1.09)])
def test_shipped_blocking_scenarios_in_a_handful_of_calls(n, sequence, weight):
    sc = load_scenario(scenarios_dir() / f"blocking_{n}.yaml")
    cache = CachedOracle(BlockingOracle(sc))
    r = astar.solve(sc, cache)
    assert r.sequence == sequence and r.total_weight == pytest.approx(weight)
    assert r.oracle_calls == cache.calls == len(sequence) and r.blocker_calls == 1
    assert r.to_dict()["blocker_calls"] == 1
    ucs = exact.solve(sc, BlockingOracle(sc))
    assert r.oracle_calls * 10 <= ucs.oracle_calls or n == 5  # 3 against 29 there


@pytest.mark.parametrize("seed", range(6))
def test_15_object_blocking_instances_a_tenth_of_uniform_cost(seed):
    """Random 15-object declared relations (as test_exact's instances) answered by the test double."""
    rnd = random.Random(seed)
    obstacles = tuple(f"o{i}" for i in range(15))
    problem = RelocationProblem(obstacles, {o: rnd.choice([0.05, 0.1, 0.25, 0.3, 0.5, 0.7, 1.0]) for o in obstacles},
                                "T")
    ids = obstacles + ("T",)
    blocking = {o: rnd.sample([x for x in ids if x != o], rnd.randint(0, 3)) for o in ids}
    oracle = BlockingOracle.from_relation(blocking, "T", ids)
    r, ucs = astar.solve(problem, oracle), exact.solve(problem, oracle)
    assert r.found == ucs.found and (not r.found or r.total_weight == pytest.approx(ucs.total_weight))
    assert r.oracle_calls * 10 <= max(ucs.oracle_calls, 10)


def test_heuristic_counts_shared_needs_once_and_follows_the_order():
    """T needs a and b, both need c: c counted once (0.7 to go, not 1.2). T needs y, y needs z, z needs y (no way:
    y leaves after z) or w: all three."""
    kb = astar.Knowledge({"a": 0.1, "b": 0.1, "c": 0.5}, "T")
    for o, lanes in {"T": [{"a", "b"}], "a": [{"c"}], "b": [{"c"}], "c": [set()]}.items():
        kb.lanes_known(o, frozenset(), tuple(BlockerSet(x) for x in lanes))
    assert kb.h(frozenset()) == pytest.approx(0.7)
    kb = astar.Knowledge({"y": 0.1, "z": 0.2, "w": 0.4}, "T")
    for o, lanes in {"T": [{"y"}], "y": [{"z"}], "z": [{"y"}, {"w"}]}.items():
        kb.lanes_known(o, frozenset(), tuple(BlockerSet(x) for x in lanes))
    assert kb.h(frozenset()) == pytest.approx(0.7)
    assert kb.h(frozenset({"w"})) == pytest.approx(0.3)
