"""Adapters over a feasibility oracle (the contract is relocation_common.feasibility): a set-keyed cache, the
obstacles the hand cannot grasp with the planner's reason (`no_grasp`), and, for tests of the Q-Tree layer only, a
declared blocking relation.
"""
from __future__ import annotations

from typing import Callable, Iterable, Mapping, Sequence

from relocation_common.feasibility import (
    NO_GRASP,
    BlockerSet,
    FeasibilityAnswer,
    FeasibilityOracle,
    Label,
    Query,
    ask_many,
    in_flight,
)
from relocation_common.scenario import Scenario, ScenarioError

Lanes = Mapping[str, tuple[BlockerSet, ...]]  # relocation_common.feasibility.LaneOracle's answer


class CachedOracle:
    """Set-keyed cache in front of any oracle (design sketch: feasibility depends only on the removed set).

    Answers repeated questions (object, frozenset(removed)) without asking the wrapped oracle again and counts
    the real calls in `calls`; `queries` counts every question asked of the cache. Share one instance across
    trainings to reuse a feasibility table (evaluation sweeps); read `calls` before and after to get the real
    calls of one run.
    """

    __slots__ = ("oracle", "table", "calls", "queries")

    def __init__(self, oracle: FeasibilityOracle) -> None:
        self.oracle = oracle
        self.table: dict[tuple[str, frozenset[str]], FeasibilityAnswer] = {}
        self.calls = 0
        self.queries = 0

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """The cached answer for (object, removed set); the wrapped oracle is asked on a miss."""
        self.queries += 1
        key = (object_id, frozenset(removed))
        answer = self.table.get(key)
        if answer is None:
            answer = self.oracle.feasibility(object_id, key[1])
            self.calls += 1
            self.table[key] = answer
        return answer

    @property
    def in_flight(self) -> int:
        """Questions the wrapped oracle answers at once."""
        return in_flight(self.oracle)

    def feasibility_many(self, queries: Sequence[Query],
                         on_answer: Callable[[Query, FeasibilityAnswer], None] | None = None
                         ) -> list[FeasibilityAnswer]:
        """relocation_common.feasibility.BatchOracle: the misses go to the wrapped oracle together (in parallel
        when it is a BatchOracle); each answer is kept as it arrives, so an error loses none."""
        keys = [(o, frozenset(r)) for o, r in queries]
        self.queries += len(keys)

        def keep(key: Query, answer: FeasibilityAnswer) -> None:
            if key not in self.table:
                self.table[key] = answer
                self.calls += 1

        misses = list(dict.fromkeys(k for k in keys if k not in self.table))
        if misses:
            ask_many(self.oracle, misses, keep)
        out = [self.table[k] for k in keys]
        if on_answer is not None:
            for k, a in zip(keys, out):
                on_answer(k, a)
        return out

    def lane_blockers(self, removed: frozenset[str]) -> Lanes | None:
        """The wrapped oracle's lane blockers (relocation_common.feasibility.LaneOracle), None if it has none.
        Not cached, not counted in `calls`: no motion planning."""
        lanes = getattr(self.oracle, "lane_blockers", None)
        return None if lanes is None else lanes(frozenset(removed))


def no_grasp(objects: Iterable[str], lanes: Lanes | None, known: Iterable[tuple[str, FeasibilityAnswer]],
             ask: Callable[[str], FeasibilityAnswer]) -> dict[str, str]:
    """object -> the motion planner's reason, for the `objects` the hand cannot grasp (their g_U message starts
    relocation_common.feasibility.NO_GRASP): those a `known` (object, answer) says so of, and those with no lane at
    all in `lanes` (the planner's lane_blockers) asked once with `ask(object)` (such an answer costs no planning).
    They stay obstacles, never relocated: this is what the log and the result say of them."""
    objects = list(objects)
    out = {o: a.message for o, a in known if o in objects and a.message.startswith(NO_GRASP)
           and Label(a.label) == Label.UNFEASIBLE}
    for o in objects:
        if o not in out and lanes is not None and lanes.get(o) == ():
            a = ask(o)
            if Label(a.label) == Label.UNFEASIBLE and a.message.startswith(NO_GRASP):
                out[o] = a.message
    return dict(sorted(out.items()))


class BlockingOracle:
    """TEST DOUBLE for the motion planner: a declared blocking relation ("object i becomes reachable once all
    of these are removed"), as in a scenario's `blocking:` section. Never a stand-in for the planner in the
    product. Objects not listed are reachable from the start; the target answers TARGET (g_T), an obstacle
    OBSTACLE (g_O), a blocked object UNFEASIBLE (g_U) naming its declared blockers not yet removed as one
    certain BlockerSet (the relation has one lane per object).
    """

    def __init__(self, scenario: Scenario) -> None:
        """`scenario`: a relocation_common.scenario.Scenario with a `blocking` section."""
        if scenario.blocking is None:
            raise ScenarioError(
                f"{scenario.source}: no 'blocking:' section, so the blocking oracle "
                "has nothing to answer from (it is a test double; use a scenario that declares one)")
        self._init(scenario.blocking, scenario.target_id, scenario.ids)

    @classmethod
    def from_relation(cls, blocking: Mapping[str, Iterable[str]], target_id: str,
                      ids: Iterable[str] | None = None) -> "BlockingOracle":
        """From a plain mapping id -> iterable of blocker ids (ids defaults to every id mentioned)."""
        self = cls.__new__(cls)
        if ids is None:
            ids = set(blocking) | {b for v in blocking.values() for b in v} | {target_id}
        self._init(blocking, target_id, ids)
        return self

    def _init(self, blocking: Mapping[str, Iterable[str]], target_id: str, ids: Iterable[str]) -> None:
        self.ids = frozenset(ids)
        self.target_id = target_id
        self.blocking = {k: frozenset(v) for k, v in blocking.items()}
        for k, v in self.blocking.items():
            unknown = (v | {k}) - self.ids
            if unknown:
                raise ValueError(f"blocking relation names unknown ids: {', '.join(sorted(unknown))}")

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Eq. 11 from the blocking relation; KeyError for an unknown id."""
        if object_id not in self.ids:
            raise KeyError(f"unknown object id {object_id!r}")
        if object_id in removed:
            raise ValueError(f"object {object_id!r} is already removed")
        left = self.blocking.get(object_id, frozenset()) - removed
        if left:
            return FeasibilityAnswer(Label.UNFEASIBLE, message="blocked", blockers=(BlockerSet(left),))
        return FeasibilityAnswer(Label.TARGET if object_id == self.target_id else Label.OBSTACLE)

    def lane_blockers(self, removed: frozenset[str]) -> dict[str, tuple[BlockerSet, ...]]:
        """Every object not removed -> its one lane: the declared blockers not yet removed (certain)."""
        return {o: (BlockerSet(self.blocking.get(o, frozenset()) - removed),) for o in self.ids if o not in removed}
