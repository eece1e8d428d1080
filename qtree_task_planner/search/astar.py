"""The exact minimum-weight sequence (Eq. 8) in few planner calls: lazy A* over removed sets with blockers
(docs/qtree.md). exact.solve (uniform-cost search) stays the reference.

Search (Lazy Shortest Path, Dellin & Srinivasa 2016). The cost of a removed set R is g(R) = sum of phi over R
(Eq. 8: the order does not change the weight), phi_i being obstacle i's cost (its weight times its action's factor:
problem.py, "One action model"; the weight at factor 1). A* runs on the optimistic graph G of knowledge.py: an edge
"remove o from R" or "relocate T from R" is there unless an answer or a certain blocker claim says it is unfeasible;
nothing is asked during this search. Its heuristic h (knowledge.py, 2.: the objects every path must remove before the
target, its lanes' own needs) is admissible on G, and it removes after R only the objects D(R) of knowledge.py,
3. (objects some claim not yet held on the way to the target names, all objects where an unexplained answer is in
reach), which keeps every optimal path of G. Ties of f go to the paths with fewer unverified edges (those
forced before the target counted as unverified), then to the deeper set: on a tie the search runs down one path.
The path found is then verified with real feasibility calls from the start (`_verify`; the target only from a set
known reachable: asking it first cost 2.7x the calls on random instances without lane information); the first
unfeasible answer (and its blockers) is recorded and the search repeated, with the heuristic's memo kept while no
new claim arrives. An oracle with several planner replicas (docs/architecture.md) is asked up to `in_flight`
consecutive edges of the path at once. When every edge of the optimistic optimum is feasible, its edges are
certified (the whole relocation of each: relocation_common.feasibility, "Certification"; all at once over replicas):
an edge that fails is unfeasible and the search goes on (LazySP's forward selector); when all certify it is the
proven optimum, certified end to end: the optimistic graph contains every true edge. Each (object, set) is asked at
most once.
"""
from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search.exact import ExactResult, as_problem, total_cost, why_none
from qtree_task_planner.search.knowledge import DEPTH, Knowledge
from relocation_common.feasibility import (
    FeasibilityAnswer,
    FeasibilityOracle,
    Label,
    Query,
    ask_many,
    certifies,
    certify_many,
    in_flight,
)
from relocation_common.scenario import Scenario

__all__ = ["AStarResult", "DEPTH", "Knowledge", "solve"]

# open-list entries: (f, unverified edges on the path + objects forced before the target, -depth, tie, set,
# parent set, object, unverified edges on the path)
Entry = tuple[float, int, int, int, frozenset[str], "frozenset[str] | None", "str | None", int]


@dataclass(frozen=True)
class AStarResult(ExactResult):
    """ExactResult (sets_settled: the sets expanded by all the optimistic searches) and the blocker counts."""

    blocker_calls: int = 0  # lane_blockers calls (the screen only, no motion planning)
    searches: int = 0  # optimistic A* searches (one more than the unfeasible answers that changed the path)

    def to_dict(self) -> dict[str, Any]:
        """ExactResult.to_dict plus the blocker calls and the optimistic searches."""
        return {**super().to_dict(), "blocker_calls": self.blocker_calls, "searches": self.searches}


def optimistic(obstacles: Sequence[str], phi: Mapping[str, float], target: str,
                kb: Knowledge) -> tuple[list[Query] | None, int]:
    """A* on the optimistic graph (module doc): the edges [(object, set)] of a least-weight path ending with the
    target's; None if there is none. Also returns the sets expanded."""
    tie = itertools.count()
    start: frozenset[str] = frozenset()
    h0, forced0, _ = kb.bound(start)
    if math.isinf(h0):
        return None, 0
    heap: list[Entry] = [(h0, forced0, 0, next(tie), start, None, None, 0)]
    closed: dict[frozenset[str], tuple[frozenset[str] | None, str | None]] = {}  # set -> (parent set, object)
    while heap:
        _, _, _, _, state, parent, obj, unv = heapq.heappop(heap)
        if obj == target and parent is not None:  # (a target entry's parent is its own set)
            return _path(target, parent, closed), len(closed)
        if state in closed:
            continue
        closed[state] = (parent, obj)
        g = math.fsum(phi[o] for o in state)  # fsum: exact, in any set order (PYTHONHASHSEED)
        if kb.possible(target, state):
            u = unv + (not kb.verified(target, state))
            heapq.heappush(heap, (g, u, -len(state), next(tie), state, state, target, u))
        worth = kb.relevant(state)
        for o in obstacles:
            nxt = state | {o}
            if o in state or (worth is not None and o not in worth) or nxt in closed or not kb.possible(o, state):
                continue
            _, forced, f = kb.bound(nxt)
            if not math.isinf(f):
                u = unv + (not kb.verified(o, state))
                heapq.heappush(heap, (f, u + forced + 1, -len(nxt), next(tie), nxt, state, o, u))
    return None, len(closed)


def _path(target: str, last: frozenset[str], closed: Mapping[frozenset[str], tuple[frozenset[str] | None,
                                                                                  str | None]]) -> list[Query]:
    """The edges from the empty set to `last` (parent pointers of `closed`), then the target's from `last`."""
    path: list[Query] = [(target, last)]
    grand, o = closed[last]
    while grand is not None and o is not None:  # back to the start, (None, None)
        path.append((o, grand))
        grand, o = closed[grand]
    return path[::-1]


def solve(problem: RelocationProblem | Scenario, oracle: FeasibilityOracle, depth: int = DEPTH) -> AStarResult:
    """Minimum-cost feasible relocation sequence (Eq. 8 with the costs: the weight at factor 1), proven, asking the
    oracle lazily (module doc).

    oracle: feasibility(object_id, removed) -> FeasibilityAnswer (blockers used when given); an optional
    lane_blockers(removed) (relocation_common.feasibility.LaneOracle) is called once, at the empty set."""
    problem = as_problem(problem)
    obstacles, target, phi = problem.obstacles, problem.target, problem.costs
    kb = Knowledge(phi, target, depth)
    blocker_calls = 0
    lanes = getattr(oracle, "lane_blockers", None)
    if lanes is not None:
        blocker_calls = 1
        for o, sets in (lanes(frozenset()) or {}).items():
            kb.lanes_known(o, frozenset(), tuple(sets))
    calls = searches = expanded = 0
    answers: dict[Query, FeasibilityAnswer] = {}
    while True:
        path, n = optimistic(obstacles, phi, target, kb)
        searches, expanded = searches + 1, expanded + n
        if path is None:
            return AStarResult(None, None, calls, expanded, why_none(target, answers, kb.claims,
                                                                     actions=problem.action_set),
                               blocker_calls=blocker_calls, searches=searches)
        asked, ok = _verify(path, target, kb, oracle, answers)
        calls += asked
        if ok:
            seq = tuple(o for o, _ in path)
            return AStarResult(seq, problem.weight(seq), calls, expanded, "", total_cost(problem, seq), blocker_calls,
                               searches)


def _verify(path: list[Query], target: str, kb: Knowledge, oracle: FeasibilityOracle,
            answers: dict[Query, FeasibilityAnswer]) -> tuple[int, bool]:
    """Ask the path's unasked edges from the start, up to the oracle's `in_flight` at once (planner replicas;
    one at a time otherwise), the target only from a set known reachable; stop at the first batch with an
    unfeasible answer. Then certify every edge at once (feasibility.certify_many); a failed one is recorded
    unfeasible. (questions asked, every edge feasible and certified); the answers also go to `answers`."""
    todo = [(o, s) for o, s in path if (o, s) not in kb.answers]
    asked = 0
    while todo:
        batch = [e for e in todo[:in_flight(oracle)] if e[0] != target] or todo[:1]
        got = ask_many(oracle, batch)
        answers.update(zip(batch, got))
        asked += len(batch)
        if not all([kb.record(o, s, a) for (o, s), a in zip(batch, got)]):
            return asked, False
        todo = todo[len(batch):]
    if not certifies(oracle):  # final answers: nothing to certify
        return asked, True
    failed = [(e, a) for e, a in zip(path, certify_many(oracle, path)) if Label(a.label) == Label.UNFEASIBLE]
    for (o, s), a in failed:
        answers[(o, s)] = a
        kb.record(o, s, a)
    return asked, not failed
