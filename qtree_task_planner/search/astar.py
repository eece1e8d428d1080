"""The exact minimum-weight sequence (Eq. 8) in few planner calls: lazy A* over removed sets with blockers
(docs/qtree.md). exact.solve (uniform-cost search) stays the reference.

Knowledge. A certain blocker claim (relocation_common.feasibility: an unfeasible answer whose BlockerSets are all
certain, or the oracle's `lane_blockers`) made at set S says: from S or any superset, relocating the object needs
one of its lanes cleared (all of that lane's objects removed). Uncertain sets claim nothing and are not used.

Search (Lazy Shortest Path, Dellin & Srinivasa 2016). The cost of a removed set R is g(R) = sum of phi over R
(Eq. 8: the order does not change the weight). A* runs on the optimistic graph: an edge "remove o from R" or
"relocate T from R" is there unless an answer or a claim says it is unfeasible; nothing is asked during this
search. Its heuristic h(R) = `need(T, R)`: the lightest clearing of one of the target's lanes not yet removed,
plus, for the objects of that lane, the most any one of them needs removed beyond it (recursively, `depth`
levels); a lane needing an object that must leave after it is no way. Admissible on the optimistic graph, where
every claim holds. The path found is then verified with real feasibility calls from the start (the target only
from a set known reachable: asking it first cost 2.7x the calls on random instances without lane information);
the first unfeasible answer (and its blockers) is recorded and the search repeated. An oracle with several planner
replicas (docs/architecture.md) is asked up to `in_flight` consecutive edges of the path at once. When every edge of the
optimistic optimum is feasible, its edges are certified (the whole relocation of each: relocation_common.feasibility,
"Certification"; all at once over replicas): an edge that fails is unfeasible and the search goes on (LazySP's
forward selector); when all certify it is the proven optimum, certified end to end: the optimistic graph contains
every true edge. Each (object, set) is asked at most once.
"""
from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search.exact import Claim, ExactResult, as_problem, why_none
from relocation_common.feasibility import (
    BlockerSet,
    FeasibilityAnswer,
    FeasibilityOracle,
    Label,
    Query,
    ask_many,
    certifies,
    certify_many,
    claims,
    in_flight,
)
from relocation_common.scenario import Scenario

DEPTH = 2  # levels of the blockers' own lanes in the heuristic


@dataclass(frozen=True)
class AStarResult(ExactResult):
    """ExactResult (sets_settled: the sets expanded by all the optimistic searches) and the blocker counts."""

    blocker_calls: int = 0  # lane_blockers calls (the screen only, no motion planning)
    searches: int = 0  # optimistic A* searches (one more than the unfeasible answers that changed the path)

    def to_dict(self) -> dict[str, Any]:
        """ExactResult.to_dict plus the blocker calls and the optimistic searches."""
        return {**super().to_dict(), "blocker_calls": self.blocker_calls, "searches": self.searches}


class Knowledge:
    """What the answers said: feasibility of asked edges and certain blocker claims (object -> [(S, lanes)])."""

    def __init__(self, weights: Mapping[str, float], target: str, depth: int = DEPTH) -> None:
        self.weights, self.target, self.depth = weights, target, depth
        self.answers: dict[Query, bool] = {}
        self.claims: dict[str, list[Claim]] = {}
        self._h: dict[frozenset[str], float] = {}

    def claim(self, obj: str, removed: frozenset[str], blockers: Sequence[BlockerSet]) -> None:
        """Record a certain claim (ignored unless every set is certain)."""
        if claims(blockers):
            entry = (frozenset(removed), tuple(b.objects for b in blockers))
            if entry not in self.claims.setdefault(obj, []):
                self.claims[obj].append(entry)
                self._h.clear()

    def lanes_known(self, obj: str, removed: frozenset[str], lanes: tuple[BlockerSet, ...]) -> None:
        """From lane_blockers: object -> its lanes (an empty tuple: never relocatable; certain sets only)."""
        if lanes == ():
            self.claims.setdefault(obj, []).append((frozenset(removed), ()))
            self._h.clear()
        else:
            self.claim(obj, removed, lanes)

    def record(self, obj: str, removed: frozenset[str], answer: FeasibilityAnswer) -> bool:
        """Remember an answer (and its lane blockers); whether the object was feasible."""
        ok = Label(answer.label) != Label.UNFEASIBLE
        self.answers[(obj, removed)] = ok
        if not ok:
            self.claim(obj, removed, answer.blockers)
        return ok

    def possible(self, obj: str, removed: frozenset[str]) -> bool:
        """Not known unfeasible: not answered g_U, and every applicable claim has a lane inside `removed`."""
        if self.answers.get((obj, removed)) is False:
            return False
        return all(any(b <= removed for b in lanes) for s, lanes in self.claims.get(obj, ()) if s <= removed)

    def verified(self, obj: str, removed: frozenset[str]) -> bool:
        """Whether the planner answered feasible for `obj` after `removed`."""
        return self.answers.get((obj, removed)) is True

    def h(self, removed: frozenset[str]) -> float:
        """Admissible lower bound on the weight still to remove before the target can be relocated."""
        got = self._h.get(removed)
        if got is None:
            got = self._h[removed] = self.need(self.target, removed, removed, frozenset(), self.depth)
        return got

    def need(self, obj: str, removed: frozenset[str], free: frozenset[str], chain: frozenset[str], depth: int) -> float:
        """Weight outside `free` that must be removed before `obj` (objects of `chain` leave after it)."""
        best = 0.0
        for s, lanes in self.claims.get(obj, ()):
            if not s <= removed:
                continue
            low = math.inf
            for b in lanes:
                if b & chain or obj in b:
                    continue
                rest = b - free
                v = math.fsum(self.weights.get(y, math.inf) for y in rest)
                if depth and rest and v < low:
                    sub = free | b
                    v += max(self.need(y, removed, sub, chain | {obj}, depth - 1) for y in rest)
                low = min(low, v)
            best = max(best, low)
        return best


def _optimistic(obstacles: Sequence[str], phi: Mapping[str, float], target: str,
                kb: Knowledge) -> tuple[list[Query] | None, int]:
    """A* on the optimistic graph: the edges [(object, set)] of a least-weight path ending with the target's,
    ties to fewer unverified edges; None if there is none. Also returns the sets expanded."""
    tie = itertools.count()
    start: frozenset[str] = frozenset()
    h0 = kb.h(start)
    if math.isinf(h0):
        return None, 0
    # entries: (f, unverified edges, -depth, tie, set, parent set, object)
    heap: list[tuple[float, int, int, int, frozenset[str], frozenset[str] | None, str | None]] = [
        (h0, 0, 0, next(tie), start, None, None)]
    closed: dict[frozenset[str], tuple[frozenset[str] | None, str | None]] = {}  # set -> (parent set, object)
    while heap:
        f, unv, _, _, state, parent, obj = heapq.heappop(heap)
        if obj == target and parent is not None:  # (a target entry's parent is its own set)
            path: list[Query] = [(target, parent)]
            grand, o = closed[parent]
            while grand is not None and o is not None:  # back to the start, (None, None)
                path.append((o, grand))
                grand, o = closed[grand]
            return path[::-1], len(closed)
        if state in closed:
            continue
        closed[state] = (parent, obj)
        g = math.fsum(phi[o] for o in state)  # fsum: exact, in any set order (PYTHONHASHSEED)
        if kb.possible(target, state):
            heapq.heappush(heap, (g, unv + (not kb.verified(target, state)), -len(state), next(tie), state, state,
                                  target))
        for o in obstacles:
            nxt = state | {o}
            if o in state or nxt in closed or not kb.possible(o, state):
                continue
            h = kb.h(nxt)
            if not math.isinf(h):
                heapq.heappush(heap, (g + phi[o] + h, unv + (not kb.verified(o, state)), -len(nxt), next(tie), nxt,
                                      state, o))
    return None, len(closed)


def solve(problem: RelocationProblem | Scenario, oracle: FeasibilityOracle, depth: int = DEPTH) -> AStarResult:
    """Minimum-weight feasible relocation sequence (Eq. 8), proven, asking the oracle lazily (module doc).

    oracle: feasibility(object_id, removed) -> FeasibilityAnswer (blockers used when given); an optional
    lane_blockers(removed) (relocation_common.feasibility.LaneOracle) is called once, at the empty set."""
    problem = as_problem(problem)
    obstacles, target, phi = problem.obstacles, problem.target, problem.weights
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
        path, n = _optimistic(obstacles, phi, target, kb)
        searches, expanded = searches + 1, expanded + n
        if path is None:
            return AStarResult(None, None, calls, expanded, why_none(target, answers, kb.claims), blocker_calls,
                               searches)
        asked, ok = _verify(path, target, kb, oracle, answers)
        calls += asked
        if ok:
            seq = tuple(o for o, _ in path)
            return AStarResult(seq, problem.weight(seq), calls, expanded, "", blocker_calls, searches)


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
