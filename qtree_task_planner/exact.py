"""The exact minimum-weight answer: the relocation sequence of least total weight (Eq. 8) that frees the target.

Feasibility depends only on the set of removed objects, so the search runs over removed sets. `solve` is a
uniform-cost search (Dijkstra; weights phi_i > 0) with lazy edge evaluation in the spirit of Lazy Shortest
Path: an edge "remove object o from set S" enters the queue with its cost g(S) + phi_o unchecked, and the oracle
is asked only when that entry is popped and its head set S + {o} is not settled yet. "Relocate the target from
S" enters at cost g(S) and is checked when popped; the first feasible one popped is optimal, since every entry
still queued costs at least as much and costs never decrease along a path. An oracle with several planner
replicas (docs/architecture.md) is asked the next cheapest queued questions together with the one popped.

`brute_force` enumerates every set reachable by feasible single removals (reachable.py, asking everything) for
tests.
"""
from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass

from relocation_common.feasibility import Label, ask_many, in_flight

from .oracles import CachedOracle
from .problem import RelocationProblem
from .reachable import reachable_sets


@dataclass(frozen=True)
class ExactResult:
    """The minimum-weight sequence (Eq. 8) and what finding it cost."""

    sequence: tuple[str, ...] | None  # obstacles in order, then the target; None if the target cannot be freed
    total_weight: float | None  # Eq. 8
    oracle_calls: int  # distinct (object, removed set) questions asked
    sets_settled: int

    @property
    def found(self) -> bool:
        """Whether the target can be freed."""
        return self.sequence is not None

    def to_dict(self) -> dict:
        """Plain data (JSON)."""
        return {"found": self.found, "sequence": list(self.sequence) if self.sequence is not None else None,
                "total_weight": self.total_weight, "oracle_calls": self.oracle_calls,
                "sets_settled": self.sets_settled}


def as_problem(problem) -> RelocationProblem:
    """`problem` itself if it is a RelocationProblem, else the problem of that scenario."""
    return problem if isinstance(problem, RelocationProblem) else RelocationProblem.from_scenario(problem)


def solve(problem, oracle) -> ExactResult:
    """Minimum-weight feasible relocation sequence by lazy uniform-cost search over removed sets.

    oracle: feasibility(object_id, removed: frozenset) -> FeasibilityAnswer. oracle_calls counts the questions
    this search asks (each (object, set) at most once, so a CachedOracle in front changes nothing here)."""
    problem = as_problem(problem)
    obstacles, target, phi = problem.obstacles, problem.target, problem.weights
    calls = 0
    known: dict = {}  # (object, set) -> answer
    settled: dict[frozenset[str], tuple[float, tuple[str, ...]]] = {}
    tie = itertools.count()
    # entries: (cost, tie, parent set, parent sequence, object)
    queue: list = [(0.0, next(tie), None, (), None)]
    while queue:
        cost, _, parent, seq, obj = heapq.heappop(queue)
        if obj is None:  # the start: the empty set, feasible by definition
            state, new_seq = frozenset[str](), ()
        else:
            state = parent if obj == target else parent | {obj}
            if obj != target and state in settled:
                continue
            if (obj, parent) not in known:
                calls += _ask_next(queue, (obj, parent), oracle, known, settled, target)
            label = Label(known[(obj, parent)].label)
            if label == Label.UNFEASIBLE:
                continue
            if obj == target:
                return ExactResult(seq + (target,), problem.weight(seq), calls, len(settled))
            new_seq = seq + (obj,)
        settled[state] = (cost, new_seq)
        heapq.heappush(queue, (cost, next(tie), state, new_seq, target))
        for o in obstacles:
            if o not in state and (state | {o}) not in settled:
                heapq.heappush(queue, (cost + phi[o], next(tie), state, new_seq, o))
    return ExactResult(None, None, calls, len(settled))


def _ask_next(queue, question, oracle, known, settled, target) -> int:
    """Ask `question` and, for an oracle with several questions in flight (planner replicas), the
    next cheapest ones still queued whose sets are not settled, together; the answers go to `known`. Returns the
    number of questions asked (1 for a plain oracle: the search asks exactly what it pops)."""
    batch, popped, k = [question], [], in_flight(oracle)
    while queue and len(batch) < k:
        entry = heapq.heappop(queue)
        popped.append(entry)
        _, _, parent, _, obj = entry
        if obj is None or (obj, parent) in known or (obj, parent) in batch:
            continue
        if obj == target or (parent | {obj}) not in settled:
            batch.append((obj, parent))
    for entry in popped:
        heapq.heappush(queue, entry)
    known.update(zip(batch, ask_many(oracle, batch)))
    return len(batch)


def brute_force(problem, oracle) -> ExactResult:
    """Test reference: every removed set reachable by feasible single removals, asking the oracle about every
    (object, reachable set) pair, then the lightest set from which the target is feasible."""
    problem = as_problem(problem)
    cache = oracle if isinstance(oracle, CachedOracle) else CachedOracle(oracle)
    calls0 = cache.calls
    reachable = reachable_sets(problem.obstacles, lambda o, s: cache.feasibility(o, s).label != Label.UNFEASIBLE)
    best = None
    for s, seq in reachable.items():
        if cache.feasibility(problem.target, s).label == Label.TARGET:
            w = problem.weight(seq)
            if best is None or w < best[0]:
                best = (w, seq + (problem.target,))
    calls = cache.calls - calls0
    if best is None:
        return ExactResult(None, None, calls, len(reachable))
    return ExactResult(best[1], best[0], calls, len(reachable))
