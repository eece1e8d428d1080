"""The blocker A*'s pruning (qtree_task_planner.search.knowledge: forced objects, objects worth removing) against the
uniform-cost reference (exact.solve) on many seeded random instances of up to 12 obstacles: several lanes per object,
objects without any lane, lane information for only some objects, blockers exact, only in answers, as subsets,
partly uncertain or absent, failures no blocker explains, weights with and without ties. The same optimal weight
every time, each question asked once; the call counts are printed (pytest -s) and compared in total."""
import heapq
import importlib.util
import itertools
import math
import random
import sys
from pathlib import Path

import pytest
from test_astar import LaneOracle, check_sequence

from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import astar, exact
from relocation_common.feasibility import BlockerSet, FeasibilityAnswer, Label

MODES = ("exact", "answers", "subset", "uncertain", "none", "partial")
SEEDS = range(600)  # fixed before any result


class PartLaneOracle(LaneOracle):
    """lane_blockers names only some objects (the rest: no information), as a screen that knows part of the scene."""

    def lane_blockers(self, removed):
        known = random.Random(self.seed * 7919 + 1).random()
        lanes = super().lane_blockers(removed)
        return {o: sets for o, sets in lanes.items() if random.Random(f"{self.seed}|{o}").random() < known}


def instance(seed: int):
    """A random instance: n in 0..12, 0-3 lanes per object of 0-4 objects, a mode, a failure rate, weights."""
    rnd = random.Random(seed)
    n = rnd.randint(0, 12)
    obstacles = tuple(f"o{i}" for i in range(n))
    if rnd.random() < 0.5:
        weights = {o: rnd.choice([0.05, 0.1, 0.25, 0.3, 0.5, 0.7, 1.0]) for o in obstacles}  # many ties
    else:
        weights = {o: round(rnd.uniform(0.01, 1.0), 3) for o in obstacles}
    ids = obstacles + ("T",)
    lanes = {}
    for o in ids:
        pop = [x for x in ids if x != o]
        k = rnd.choice([1, 1, 2, 2, 3] if o == "T" else [0, 1, 1, 1, 2, 3])
        lanes[o] = [frozenset(rnd.sample(pop, rnd.randint(0, min(4, len(pop))))) for _ in range(k)]
    mode = rnd.choice(MODES)
    p_fail = rnd.choice([0.0, 0.0, 0.0, 0.1, 0.3])
    cls = PartLaneOracle if mode == "partial" else LaneOracle
    return RelocationProblem(obstacles, weights, "T"), cls(seed, lanes, "T", "exact" if mode == "partial" else mode,
                                                             p_fail)


def test_astar_proves_the_uniform_cost_optimum_on_600_random_instances():
    calls = {"astar": 0, "ucs": 0}
    found = 0
    for seed in SEEDS:
        problem, oracle = instance(seed)
        ref = exact.solve(problem, oracle)
        oracle.asked.clear()
        r = astar.solve(problem, oracle)
        assert len(oracle.asked) == len(set(oracle.asked)) == r.oracle_calls, seed  # each question once
        assert r.found == ref.found, (seed, r, ref)
        if r.found:
            assert r.total_weight == pytest.approx(ref.total_weight, abs=1e-9), (seed, r.sequence, ref.sequence)
            check_sequence(problem, oracle, r)
            found += 1
        calls["astar"] += r.oracle_calls
        calls["ucs"] += ref.oracle_calls
    print(f"\n{len(SEEDS)} instances ({found} solvable): oracle calls A* {calls['astar']}, uniform-cost "
          f"{calls['ucs']} ({calls['astar'] / calls['ucs']:.3f})")
    assert calls["astar"] < calls["ucs"]


def random_knowledge(seed: int):
    """Arbitrary knowledge over up to 8 obstacles: certain claims made at random sets (several lanes, none at all,
    lanes naming the target), g_U answers with and without claims, some answers feasible."""
    rnd = random.Random(seed)
    n = rnd.randint(1, 8)
    obstacles = tuple(f"o{i}" for i in range(n))
    weights = {o: rnd.choice([0.05, 0.1, 0.25, 0.3, 0.5, 0.7, 1.0]) for o in obstacles}
    ids = obstacles + ("T",)
    kb = astar.Knowledge(weights, "T")
    for _ in range(rnd.randint(0, 3 * n)):
        o = rnd.choice(ids)
        pop = [x for x in ids if x != o]
        s = frozenset(rnd.sample([x for x in obstacles if x != o], rnd.randint(0, min(3, n - (o != "T")))))
        lanes = tuple(BlockerSet(rnd.sample([x for x in pop if x not in s], rnd.randint(0, min(3, len(pop) - len(s)))))
                      for _ in range(rnd.choice([0, 1, 1, 2, 3])))
        kind = rnd.random()
        if kind < 0.4:
            kb.lanes_known(o, s, lanes)
        else:  # an answer: g_U with these lanes, uncertain ones, none; or feasible
            ok = kind > 0.9
            blockers = lanes if kind < 0.6 else tuple(BlockerSet(b.objects, certain=False) for b in lanes)
            kb.record(o, s, FeasibilityAnswer(Label.OBSTACLE if ok else Label.UNFEASIBLE, blockers=blockers))
    return RelocationProblem(obstacles, weights, "T"), kb


def optimistic_optimum(problem, kb):
    """Reference: the least weight of a path of the optimistic graph (every edge kb.possible), by uniform-cost search
    over every removed set, no pruning, no heuristic."""
    best = {frozenset(): 0.0}
    heap = [(0.0, 0, frozenset())]
    tie = 0
    while heap:
        g, _, s = heapq.heappop(heap)
        if g > best[s]:
            continue
        if kb.possible(problem.target, s):
            return g
        for o in problem.obstacles:
            if o not in s and kb.possible(o, s):
                t, w = s | {o}, g + problem.weights[o]
                if w < best.get(t, math.inf) - 1e-12:
                    best[t] = w
                    tie += 1
                    heapq.heappush(heap, (w, tie, t))
    return None


def test_pruning_and_heuristic_keep_the_optimistic_optimum_on_3000_random_knowledge_states():
    """knowledge.py's rules 1-3 on arbitrary knowledge (claims made at any set, unexplained answers): the pruned A*
    finds a path of the optimistic graph as light as the unpruned search's, and h never exceeds the cost to go from
    any set."""
    for seed in range(3000):
        problem, kb = random_knowledge(seed)
        ref = optimistic_optimum(problem, kb)
        path, _ = astar.optimistic(problem.obstacles, problem.weights, problem.target, kb)
        assert (path is None) == (ref is None), (seed, path, ref)
        if path is not None:
            removed = frozenset()
            for o, s in path:
                assert s == removed and kb.possible(o, s), (seed, path)
                removed |= {o}
            assert problem.weight(o for o, _ in path) == pytest.approx(ref, abs=1e-9), (seed, path, ref)
        for s, to_go in cost_to_go(problem, kb).items():
            assert kb.h(s) <= to_go + 1e-9, (seed, sorted(s))


def cost_to_go(problem, kb):
    """Every removed set -> the least weight of a path of the optimistic graph from it to the target (infinity:
    none), by dynamic programming from the full set down."""
    out = {}
    obstacles = problem.obstacles
    for k in range(len(obstacles), -1, -1):
        for s in map(frozenset, itertools.combinations(obstacles, k)):
            out[s] = 0.0 if kb.possible(problem.target, s) else min(
                (problem.weights[o] + out[s | {o}] for o in obstacles if o not in s and kb.possible(o, s)),
                default=math.inf)
    return out


def _scale_bench():
    """scripts/bench_search_scale.py as a module (its layered relations are the scale benchmark's)."""
    path = Path(__file__).resolve().parents[1] / "scripts" / "bench_search_scale.py"
    spec = importlib.util.spec_from_file_location("bench_search_scale", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("n", [30, 60, 100])
def test_layered_relations_expand_about_one_set_per_relocation(n):
    """Random layered relations (one lane per object, lanes known; the scale benchmark's, seeds 0-4): the optimum is
    the closure of the target's blockers, proven in one question per relocation and at most twice as many sets
    expanded. (The A* before the forced-object bound expanded 555-3,222 sets at n = 30 and ran for minutes at 60.)"""
    bench = _scale_bench()
    for seed in range(5):
        problem, oracle, closure = bench.layered(seed, n)
        r = astar.solve(problem, oracle)
        assert r.total_weight == pytest.approx(math.fsum(problem.weights[o] for o in closure), abs=1e-9), seed
        assert r.oracle_calls == len(closure) + 1 and r.searches == 1, seed
        assert r.sets_settled <= 2 * (len(closure) + 1), (seed, r.sets_settled, len(closure))
