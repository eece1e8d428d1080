"""Adapters over a feasibility oracle (the contract is relocation_common.feasibility): a set-keyed cache with reuse
across answers and lazy certification, the obstacles the hand cannot grasp with the planner's reason (`no_grasp`),
and, for tests of the Q-Tree layer only, a declared blocking relation.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Iterable, Mapping, Sequence

from relocation_common.feasibility import (
    NO_GRASP,
    BlockerSet,
    FeasibilityAnswer,
    FeasibilityOracle,
    Label,
    Query,
    ask_many,
    certifies,
    certify_many,
    claim_holds,
    in_flight,
    is_pick,
    reuses,
)
from relocation_common.scenario import Scenario, ScenarioError

Lanes = Mapping[str, tuple[BlockerSet, ...]]  # relocation_common.feasibility.LaneOracle's answer


class CachedOracle:
    """Set-keyed cache in front of any oracle (design sketch: feasibility depends only on the removed set), with
    reuse across answers and lazy certification (relocation_common.feasibility, "Certification" and "Reuse").

    Answers repeated questions (object, frozenset(removed)) without asking the wrapped oracle again and counts the
    real calls in `calls`; `queries` counts every question asked of the cache. A question not in the table is
    answered without asking (`reused`: those questions) when an answer the oracle gave for the same object holds for it:
    a feasible one whose motion comes near none of the objects removed then and present now (feasibility.reuses),
    or an unfeasible one whose certain blocker sets all stay uncleared (feasibility.claim_holds); with `reuse`
    False (the default: a plain cache, whose calls count the distinct questions) every new question is asked. The
    task planner node reuses (its `reuse_answers`). Share one instance across trainings to reuse a feasibility
    table (evaluation sweeps); read `calls` before and after to get the real calls of one run.

    Certifications are kept apart (`certified`, real ones counted in `cert_calls`): `certify(o, R)` asks once; a
    failed one turns the table's answer for (o, R) UNFEASIBLE with the certification's reason, so every search and
    training from then on sees it unfeasible. Only a pick alone is certified (feasibility.is_pick: feasible, with its
    near set); any other answer, or any answer of an oracle without `certify`, is final: its own certification.
    """

    __slots__ = ("oracle", "table", "calls", "queries", "reuse", "reused", "certified", "cert_calls", "_sources")

    def __init__(self, oracle: FeasibilityOracle, reuse: bool = False) -> None:
        self.oracle = oracle
        self.table: dict[tuple[str, frozenset[str]], FeasibilityAnswer] = {}
        self.calls = 0
        self.queries = 0
        self.reuse = reuse
        self.reused: set[Query] = set()
        self.certified: dict[tuple[str, frozenset[str]], FeasibilityAnswer] = {}
        self.cert_calls = 0
        self._sources: dict[str, list[tuple[frozenset[str], FeasibilityAnswer]]] = {}  # object -> answers asked

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """The cached answer for (object, removed set); reused, or the wrapped oracle asked, on a miss."""
        self.queries += 1
        key = (object_id, frozenset(removed))
        answer = self.table.get(key) or self._reused(key)
        if answer is None:
            answer = self.oracle.feasibility(object_id, key[1])
            self.calls += 1
            self.put(key, answer)
        return answer

    def put(self, key: Query, answer: FeasibilityAnswer) -> None:
        """Keep an answer the oracle gave for `key` (a source of reuse too)."""
        self.table[key] = answer
        if self.reuse:
            self._sources.setdefault(key[0], []).append((key[1], answer))

    def _reused(self, key: Query) -> FeasibilityAnswer | None:
        """The answer of `key` from an answer of the same object that holds for it (class docstring), kept in the
        table; None when none does."""
        obj, removed = key
        for was, a in self._sources.get(obj, ()):
            if reuses(a, was, removed):
                got = a
            elif claim_holds(a, was, removed):
                got = dataclasses.replace(a, blockers=tuple(dataclasses.replace(b, objects=b.objects - removed)
                                                            for b in a.blockers))
            else:
                continue
            self.table[key] = got
            self.reused.add(key)
            return got
        return None

    @property
    def planner_answers(self) -> int:
        """Answers the planner gave behind this cache: the table's answers not reused (a checkpoint's included) and
        the certifications asked."""
        return len(self.table) - len(self.reused) + self.cert_calls

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
                self.put(key, answer)
                self.calls += 1

        misses = list(dict.fromkeys(k for k in keys if k not in self.table and self._reused(k) is None))
        if misses:
            ask_many(self.oracle, misses, keep)
        out = [self.table[k] for k in keys]
        if on_answer is not None:
            for k, a in zip(keys, out):
                on_answer(k, a)
        return out

    # -- certification ---------------------------------------------------------------------------------------
    def certify(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """The certification of (object, removed set) (relocation_common.feasibility.CertifyingOracle), asked once."""
        return self.certify_many([(object_id, frozenset(removed))])[0]

    def certify_many(self, queries: Sequence[Query],
                     on_answer: Callable[[Query, FeasibilityAnswer], None] | None = None) -> list[FeasibilityAnswer]:
        """Every query's certification, the ones not yet known asked together (in parallel over replicas:
        feasibility.certify_many); an answer that is no pick alone (unfeasible, or final: feasibility.is_pick) is its
        own certification."""
        keys = [(o, frozenset(r)) for o, r in queries]
        certifying = certifies(self.oracle)
        for k in keys:
            if k not in self.certified:
                pick = self.table.get(k) or self.feasibility(*k)
                if not (certifying and is_pick(pick)):
                    self.certified[k] = pick

        def keep(key: Query, answer: FeasibilityAnswer) -> None:
            if key not in self.certified:
                self.cert_calls += 1
                self.certified[key] = answer
                if Label(answer.label) == Label.UNFEASIBLE:  # the planner's answer now, reused or not
                    self.reused.discard(key)
                    self.table[key] = dataclasses.replace(answer, message=f"certification: {answer.message}",
                                                          blockers=(), trajectory=None)

        misses = list(dict.fromkeys(k for k in keys if k not in self.certified))
        if misses:
            certify_many(self.oracle, misses, keep)
        out = [self.certified[k] for k in keys]
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
