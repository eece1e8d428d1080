"""The exact minimum-weight answer: the relocation sequence of least total weight (Eq. 8) that frees the target;
with the action model, of least total cost (each obstacle's weight times its action's factor: problem.py, "One action
model"), the same sequence when every factor is 1. Eq. 8's weight is reported, the cost beside it when it differs.

Feasibility depends only on the set of removed objects, so the search runs over removed sets. `solve` is a
uniform-cost search (Dijkstra; weights phi_i > 0) with lazy edge evaluation in the spirit of Lazy Shortest
Path: an edge "remove object o from set S" enters the queue with its cost g(S) + phi_o unchecked, and the oracle
is asked only when that entry is popped and its head set S + {o} is not settled yet. "Relocate the target from
S" enters at cost g(S) and is checked when popped; the first feasible one popped is optimal, since every entry
still queued costs at least as much and costs never decrease along a path. An oracle with several planner
replicas (docs/architecture.md) is asked the next cheapest queued questions together with the one popped.

`brute_force` enumerates every set reachable by feasible single removals (reachable.py, asking everything) for
tests. When no sequence exists, `why_none` says why in one line from what the search learned (docs/motion_planner.md,
"Why there is no sequence"), naming the actions it is a proof for (the problem's action_set): the target's own
answer, a blocking cycle of certain lane blockers (through the target or not), the objects no grasp ever reached.
"""
from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search.reachable import reachable_sets
from relocation_common.feasibility import (
    PICK_ACTIONS,
    FeasibilityAnswer,
    FeasibilityOracle,
    Label,
    Query,
    action_set,
    ask_many,
    claims,
    in_flight,
)
from relocation_common.scenario import Scenario

Claim = tuple[frozenset[str], tuple[frozenset[str], ...]]  # (removed set, its lanes' blockers): a certain claim
# queue entries of `solve`: (cost, tie, parent set, parent sequence, object); the start has no parent and no object
Entry = tuple[float, int, frozenset[str] | None, tuple[str, ...], str | None]


@dataclass(frozen=True)
class ExactResult:
    """The minimum-weight sequence (Eq. 8) or None, the oracle calls it took, and why there is none."""

    sequence: tuple[str, ...] | None  # obstacles in order, then the target; None if the target cannot be freed
    total_weight: float | None  # Eq. 8
    oracle_calls: int  # distinct (object, removed set) questions asked
    sets_settled: int
    reason: str = ""  # why there is no sequence (why_none), one line; empty when found
    total_cost: float | None = None  # the sequence's total cost (problem.RelocationProblem.cost), what the search
    # minimised; None for a problem whose costs are its weights (every action factor 1: the paper's)

    @property
    def found(self) -> bool:
        """A sequence frees the target."""
        return self.sequence is not None

    def to_dict(self) -> dict[str, Any]:
        """As JSON (`qtree solve`)."""
        out = {"found": self.found, "sequence": list(self.sequence) if self.sequence is not None else None,
               "total_weight": self.total_weight, "oracle_calls": self.oracle_calls,
               "sets_settled": self.sets_settled}
        if self.total_cost is not None:  # a costed problem (an action factor other than 1)
            out["total_cost"] = self.total_cost
        return out if self.found else {**out, "reason": self.reason}


def _set(s: Iterable[str]) -> str:
    return "{" + ", ".join(sorted(s)) + "}"


def why_none(target: str, asked: Mapping[Query, FeasibilityAnswer], lanes: Mapping[str, Sequence[Claim]] | None = None,
             limit: int = 4, actions: Sequence[str] = PICK_ACTIONS) -> str:
    """One line saying why no sequence of `actions` (the problem's action_set: what it is a proof for, named first:
    "no sequence with the actions side_grasp, top_grasp: ...") frees `target`, from the answers asked ((object,
    removed) -> answer) and
    certain lane claims (object -> [(removed, lane sets)], e.g. astar.Knowledge.claims; the answers' own certain
    blockers are added): the target's answer from the largest set reached; a blocking cycle (every lane of the
    target needs an object that can never leave first: each of its lanes needs the target or another such object
    moved, or it has no lane at all); the objects
    never feasible in any set asked, with the planner's reason."""
    claimed = {o: list(v) for o, v in (lanes or {}).items()}
    for (o, s), a in asked.items():
        if Label(a.label) == Label.UNFEASIBLE and claims(a.blockers):
            claimed.setdefault(o, []).append((s, tuple(b.objects for b in a.blockers)))
    parts = []
    mine = [(s, a) for (o, s), a in asked.items() if o == target]
    if mine:
        s, a = max(mine, key=lambda x: (len(x[0]), sorted(x[0])))
        parts.append(f"{target} unfeasible from every set reached (with {_set(s)} removed: {a.message})")
    elif any(ls == () for _, ls in claimed.get(target, ())):
        parts.append(f"{target} has no grasp lane that removing bottles can clear (boards or reach)")
    cycle = _cycle(target, claimed)
    if cycle:
        parts.append(cycle)
    last: dict[str, tuple[frozenset[str], FeasibilityAnswer]] = {}  # object -> (largest set asked, its answer),
    # for objects never feasible
    feasible = {o for (o, _), a in asked.items() if Label(a.label) != Label.UNFEASIBLE}
    for (o, s), a in asked.items():
        if o != target and o not in feasible and (o not in last or len(s) > len(last[o][0])):
            last[o] = (s, a)
    stuck = [f"{o} ({a.message})" for o, (_, a) in sorted(last.items())]
    if stuck:
        more = f"; {len(stuck) - limit} more" if len(stuck) > limit else ""
        parts.append("never feasible: " + "; ".join(stuck[:limit]) + more)
    return no_sequence(actions) + (". ".join(parts) if parts else "nothing was feasible to ask")


def no_sequence(actions: Sequence[str]) -> str:
    """The start of a "no sequence" proof, naming the actions it covers: 'no sequence with the actions side_grasp,
    top_grasp: '."""
    return f"no sequence with {action_set(actions)}: "


def _cycle(target: str, lanes: Mapping[str, Sequence[Claim]], limit: int = 8) -> str:
    """'blocking cycle: ...' if no lane of the target (claimed at the empty set) can be cleared: every lane needs an
    object that can never leave before the target, because each of its lanes needs the target or another such
    object moved, or it has no lane ('' otherwise; at most `limit` explanations). Objects without a claim count as
    able to leave (optimistic)."""
    walk = _cycle_walk(target, lanes)
    if walk is None:
        return ""
    first, free, by_lane, behind = walk
    parts = [f"lane {_set(lane)}: {_needs(x, first, free)}" for lane, x in by_lane]
    parts += [_needs(y, first, free) for y in behind]
    more = f"; {len(parts) - limit} more" if len(parts) > limit else ""
    return f"blocking cycle: every lane of {target} needs an object that cannot leave first (" + \
        "; ".join(parts[:limit]) + more + ")"


def blocking_needs(target: str, lanes: Mapping[str, Sequence[Claim]]) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """The blocking cycle `_cycle` names, as data: (x, the objects x needs moved) for each object explained there
    ("x needs T moved", "x needs one of {a, b} moved"), in the line's order (an object with no lane at all
    left out); () when there is no cycle. What a push can open (qtree_task_planner.executive.push)."""
    walk = _cycle_walk(target, lanes)
    if walk is None:
        return ()
    first, free, by_lane, behind = walk
    out: dict[str, tuple[str, ...]] = {}
    for x in [x for _, x in by_lane] + behind:
        out.setdefault(x, tuple(_stuck(x, first, free)))
    return tuple((x, stuck) for x, stuck in out.items() if stuck)


def laneless_blockers(target: str, lanes: Mapping[str, Sequence[Claim]]) -> tuple[str, ...]:
    """The objects the blocking cycle `_cycle` names in a lane of the target that have no lane of their own ("x has
    no lane": a bottle lying where no grasp reaches it), sorted; () when there is no cycle. No pick order moves
    them: a push of such an object out of the target's lanes is what can open the cycle
    (qtree_task_planner.executive.push)."""
    walk = _cycle_walk(target, lanes)
    if walk is None:
        return ()
    first, _, by_lane, _ = walk
    return tuple(sorted({x for _, x in by_lane if not first[x]}))


def laneless_in_lanes(target: str, lanes: Mapping[str, Sequence[Claim]]) -> tuple[str, ...]:
    """The objects with no lane of their own (claimed at the empty set: a bottle lying where no grasp reaches it) in
    a lane of the target, sorted, whether or not the proof is a blocking cycle. Where the target is unfeasible from
    every set the search reached (its lanes free of such objects failed in the motion planner), a push of one of
    them out of the target's lanes still opens a lane the screen holds shut (qtree_task_planner.executive.push)."""
    first = _first_lanes(lanes)
    return tuple(sorted({m for lane in first.get(target, ()) for m in lane if m in first and not first[m]}))


def _cycle_walk(target: str, lanes: Mapping[str, Sequence[Claim]]
                ) -> tuple[dict[str, tuple[frozenset[str], ...]], set[str], list[tuple[frozenset[str], str]],
                           list[str]] | None:
    """The blocking cycle of `_cycle` (None: there is none): each object's first lanes (claimed at the empty set),
    the objects that can leave, (lane of the target, the object of it that cannot leave) for each lane, then every
    object stuck behind those, each once."""
    first = _first_lanes(lanes)
    if not first.get(target):
        return None
    free = _leaving(target, first)
    if any(set(lane) <= free for lane in first[target]):
        return None
    by_lane, told = [], {target}
    for lane in sorted({frozenset(lane) for lane in first[target]}, key=lambda ls: (len(ls), sorted(ls))):
        x = next(m for m in sorted(lane) if m not in free)
        by_lane.append((lane, x))
        told.add(x)
    behind = []
    todo = sorted({m for lane in first[target] for m in lane if m not in free})
    seen = set(todo) | {target}
    while todo:  # every object stuck behind those, each explained once
        y = todo.pop(0)
        if y not in told:
            behind.append(y)
            told.add(y)
        for m in sorted({m for lane in first[y] for m in lane if m not in free} - seen):
            seen.add(m)
            todo.append(m)
    return first, free, by_lane, behind


def _first_lanes(lanes: Mapping[str, Sequence[Claim]]) -> dict[str, tuple[frozenset[str], ...]]:
    """Each object's first lanes: those of its first claim made at the empty set."""
    return {o: v[0] for o, v in ((o, [ls for s, ls in c if not s]) for o, c in lanes.items()) if v}


def _leaving(target: str, first: Mapping[str, tuple[frozenset[str], ...]]) -> set[str]:
    """The objects that can leave before the target: those named in a lane without a claim of their own
    (optimistic), and, grown to a fixpoint, every object with a lane of such objects only."""
    free = {m for ls in first.values() for lane in ls for m in lane if m not in first} - {target}
    grown = True
    while grown:
        grown = False
        for o, ls in first.items():
            if o != target and o not in free and any(set(lane) <= free for lane in ls):
                free.add(o)
                grown = True
    return free


def can_leave(target: str, lanes: Mapping[str, Sequence[Claim]]) -> tuple[str, ...]:
    """The objects a blocking cycle's proof says can leave first (the picks alone take them away before the
    target, as far as the certain claims at the empty set tell: `_cycle`'s fixpoint), sorted; () when the target
    has no claim. What a push may need gone first (qtree_task_planner.executive.push)."""
    first = _first_lanes(lanes)
    return tuple(sorted(_leaving(target, first))) if first.get(target) else ()


def _stuck(x: str, first: Mapping[str, tuple[frozenset[str], ...]], free: set[str]) -> list[str]:
    """The objects in x's lanes that cannot leave first (sorted)."""
    return sorted({m for lane in first[x] for m in lane if m not in free})


def _needs(x: str, first: Mapping[str, tuple[frozenset[str], ...]], free: set[str]) -> str:
    """'x needs T moved', 'x needs one of {a, b} moved' (the objects stuck in its lanes) or 'x has no lane'."""
    stuck = _stuck(x, first, free)
    if not first[x]:
        return f"{x} has no lane"
    return f"{x} needs {stuck[0]} moved" if len(stuck) == 1 else f"{x} needs one of {_set(stuck)} moved"


def as_problem(problem: RelocationProblem | Scenario) -> RelocationProblem:
    """`problem` itself if it is a RelocationProblem, else the problem of that scenario."""
    return problem if isinstance(problem, RelocationProblem) else RelocationProblem.from_scenario(problem)


def solve(problem: RelocationProblem | Scenario, oracle: FeasibilityOracle) -> ExactResult:
    """Minimum-cost (Eq. 8; the weight at factor 1) feasible relocation sequence by lazy uniform-cost search over
    removed sets.

    oracle: feasibility(object_id, removed: frozenset) -> FeasibilityAnswer. oracle_calls counts the questions
    this search asks (each (object, set) at most once, so a CachedOracle in front changes nothing here)."""
    problem = as_problem(problem)
    obstacles, target, phi = problem.obstacles, problem.target, problem.costs
    calls = 0
    known: dict[Query, FeasibilityAnswer] = {}  # (object, set) -> answer
    settled: dict[frozenset[str], tuple[float, tuple[str, ...]]] = {}
    tie = itertools.count()
    queue: list[Entry] = [(0.0, next(tie), None, (), None)]
    state: frozenset[str]
    new_seq: tuple[str, ...]
    while queue:
        cost, _, parent, seq, obj = heapq.heappop(queue)
        if obj is None or parent is None:  # the start: the empty set, feasible by definition
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
                return ExactResult(seq + (target,), problem.weight(seq), calls, len(settled),
                                   total_cost=total_cost(problem, seq))
            new_seq = seq + (obj,)
        settled[state] = (cost, new_seq)
        heapq.heappush(queue, (cost, next(tie), state, new_seq, target))
        for o in obstacles:
            if o not in state and (state | {o}) not in settled:
                heapq.heappush(queue, (cost + phi[o], next(tie), state, new_seq, o))
    return ExactResult(None, None, calls, len(settled), why_none(target, known, actions=problem.action_set))


def _ask_next(queue: list[Entry], question: Query, oracle: FeasibilityOracle, known: dict[Query, FeasibilityAnswer],
              settled: Mapping[frozenset[str], object], target: str) -> int:
    """Ask `question` and, for an oracle with several questions in flight (planner replicas), the
    next cheapest ones still queued whose sets are not settled, together; the answers go to `known`. Returns the
    number of questions asked (1 for a plain oracle: the search asks exactly what it pops)."""
    batch, popped, k = [question], [], in_flight(oracle)
    while queue and len(batch) < k:
        entry = heapq.heappop(queue)
        popped.append(entry)
        _, _, parent, _, obj = entry
        if obj is None or parent is None or (obj, parent) in known or (obj, parent) in batch:
            continue
        if obj == target or (parent | {obj}) not in settled:
            batch.append((obj, parent))
    for entry in popped:
        heapq.heappush(queue, entry)
    known.update(zip(batch, ask_many(oracle, batch)))
    return len(batch)


def brute_force(problem: RelocationProblem | Scenario, oracle: FeasibilityOracle) -> ExactResult:
    """Test reference: every removed set reachable by feasible single removals, asking the oracle about every
    (object, reachable set) pair, then the lightest set from which the target is feasible."""
    problem = as_problem(problem)
    cache = oracle if isinstance(oracle, CachedOracle) else CachedOracle(oracle)
    calls0 = cache.calls
    reachable = reachable_sets(problem.obstacles, lambda o, s: cache.feasibility(o, s).label != Label.UNFEASIBLE)
    best = None
    for s, seq in reachable.items():
        if cache.feasibility(problem.target, s).label == Label.TARGET:
            c = problem.cost(seq)
            if best is None or c < best[0]:
                best = (c, seq + (problem.target,))
    calls = cache.calls - calls0
    if best is None:
        return ExactResult(None, None, calls, len(reachable))
    return ExactResult(best[1], problem.weight(best[1]), calls, len(reachable), total_cost=total_cost(problem, best[1]))


def total_cost(problem: RelocationProblem, sequence: Sequence[str]) -> float | None:
    """A result's total cost (ExactResult.total_cost): the sequence's for a costed problem, None for one whose costs
    are its weights."""
    return problem.cost(sequence) if problem.costed else None
