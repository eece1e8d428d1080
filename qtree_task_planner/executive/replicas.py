"""Feasibility over several motion planner replicas (docs/architecture.md): N questions in flight, and failover.

ROS-free: each replica is an oracle (the node's ServiceOracle, one per PlanFeasibility service) with `name`,
`last_ok` and `ready(timeout)`. A replica raising PlannerUnavailable (dead, wedged, or its safety net ran out) is
*down*: its question goes to another replica, and it is asked again only after a rest, or when every other replica
is down too. The rest doubles with each failure in a row (`retry_after`, 2x, 4x ... at most `max_rest` s): a
SIGKILLed planner's service stays in the DDS graph for some 20 s and each try costs a full query timeout.
PlannerUnavailable leaves this oracle only when no replica could answer a question, so the task planner's outage
handling (outage.until_available) sees an outage only when all of them are gone.

One question at a time (`feasibility`, `certify`, `lane_blockers`) goes to the first replica that is up, in the given
order: with replica 0 up, a sequential caller (the Q-Tree's episodes) asks exactly what one planner would be asked.
`feasibility_many` and `certify_many` keep one question in flight per replica that is up
(relocation_common.feasibility.BatchOracle; a certification: feasibility.CertifyingOracle).
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Callable, Mapping, Protocol, Sequence, TypeVar

from qtree_task_planner.executive.outage import PlannerUnavailable
from qtree_task_planner.executive.push import PushAnswer
from qtree_task_planner.oracles import Lanes
from relocation_common.feasibility import (
    CertifyingOracle,
    FeasibilityAnswer,
    FeasibilityOracle,
    LaneOracle,
    Query,
    certify_many,
)

T = TypeVar("T")


class Replica(FeasibilityOracle, CertifyingOracle, LaneOracle, Protocol):
    """One motion planner's feasibility service (the node's ros_clients.ServiceOracle): Eq. 11, certifications and
    the lane blockers, its `name`, the monotonic time of its last answer `last_ok`, and whether it is up."""

    name: str
    last_ok: float

    def ready(self, timeout: float) -> bool:
        """Whether the service is up, waiting up to `timeout` s for it."""
        ...

    def push(self, object_id: str, clear_for: str, removed: frozenset[str]) -> PushAnswer:
        """The push question (qtree_task_planner.executive.push)."""
        ...

    def what_if(self, moved: Mapping[str, tuple[float, float]]) -> Replica:
        """This replica asking on the scene with `moved`'s objects at those (x, y) (what would follow a push)."""
        ...


class ReplicaOracle:
    """FeasibilityOracle, LaneOracle and BatchOracle over the replicas (the module docstring)."""

    def __init__(self, replicas: Sequence[Replica], retry_after: float = 5.0, max_rest: float = 60.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not replicas:
            raise ValueError("ReplicaOracle needs at least one replica")
        self.replicas, self.retry_after, self.max_rest, self.clock = list(replicas), retry_after, max_rest, clock
        self.down: dict[int, float] = {}  # replica index -> when it last failed
        self.failures: dict[int, int] = {}  # replica index -> failures in a row
        self.answers = [0] * len(self.replicas)  # answers per replica
        self._lock = threading.Lock()

    # -- state ----------------------------------------------------------------------------------------------
    @property
    def in_flight(self) -> int:
        """Questions answered at once: the replicas that are up (at least 1)."""
        return max(1, len(self._usable()))

    @property
    def last_ok(self) -> float:
        """Monotonic time of the last answer of any replica."""
        return max(r.last_ok for r in self.replicas)

    def ready(self, timeout: float) -> bool:
        """Some replica's service is there (waits up to `timeout` s in all)."""
        deadline = self.clock() + timeout
        while True:
            for r in self.replicas:
                if r.ready(0.0):
                    return True
            if self.clock() >= deadline:
                return False
            time.sleep(min(0.05, max(0.0, deadline - self.clock())))

    def _usable(self) -> list[int]:
        now = self.clock()
        return [i for i in range(len(self.replicas)) if i not in self.down or now - self.down[i] >= self._rest(i)]

    def _rest(self, i: int) -> float:
        return min(self.max_rest, self.retry_after * 2 ** (self.failures.get(i, 1) - 1))

    def _order(self) -> list[int]:
        """Replicas up first (in order), then the ones down, longest down first."""
        up = self._usable()
        with self._lock:
            down = dict(self.down)
        return up + sorted((i for i in down if i not in up), key=lambda i: down[i])

    def _failed(self, i: int) -> None:
        with self._lock:
            self.down[i] = self.clock()
            self.failures[i] = self.failures.get(i, 0) + 1

    def _answered(self, i: int) -> None:
        with self._lock:
            self.down.pop(i, None)
            self.failures.pop(i, None)
            self.answers[i] += 1

    def summary(self) -> str:
        """Answers per replica, the down ones marked (for the log)."""
        return ", ".join(f"{r.name}: {n} answers{' (down)' if i in self.down else ''}"
                         for i, (r, n) in enumerate(zip(self.replicas, self.answers)))

    # -- one question ---------------------------------------------------------------------------------------
    def _one(self, ask: Callable[[Replica], T], what: str) -> T:
        errors: list[tuple[str, PlannerUnavailable]] = []
        for i in self._order():
            try:
                got = ask(self.replicas[i])
            except PlannerUnavailable as e:
                self._failed(i)
                errors.append((self.replicas[i].name, e))
                continue
            self._answered(i)
            return got
        if len(errors) == 1:  # one planner: its own words
            raise errors[0][1]
        raise PlannerUnavailable(f"no replica answered {what} ({'; '.join(f'{n}: {e}' for n, e in errors)})")

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Eq. 11 from the first replica that is up (failover on PlannerUnavailable)."""
        return self._one(lambda r: r.feasibility(object_id, removed), repr(object_id))

    def certify(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """The certification of (object_id, removed) from the first replica that is up (failover); a replica that
        does not certify gives final answers (feasibility.certify_many)."""
        return self._one(lambda r: certify_many(r, [(object_id, removed)])[0], f"the certification of {object_id!r}")

    def push(self, object_id: str, clear_for: str, removed: frozenset[str]) -> PushAnswer:
        """The push question (qtree_task_planner.executive.push) of the first replica that is up."""
        return self._one(lambda r: r.push(object_id, clear_for, removed), f"the push of {object_id!r}")

    def what_if(self, moved: Mapping[str, tuple[float, float]]) -> ReplicaOracle:
        """These replicas asking on the scene with `moved`'s objects at those (x, y) (Replica.what_if: what would
        follow a push), with the rests of those that are down now."""
        other = ReplicaOracle([r.what_if(moved) for r in self.replicas], self.retry_after, self.max_rest, self.clock)
        with self._lock:
            other.down, other.failures = dict(self.down), dict(self.failures)
        return other

    def lane_blockers(self, removed: frozenset[str]) -> Lanes | None:
        """Every remaining object's lane blockers, from the first replica that is up."""
        return self._one(lambda r: r.lane_blockers(removed), "the lane blockers")

    # -- many questions -------------------------------------------------------------------------------------
    def feasibility_many(self, queries: Sequence[Query],
                         on_answer: Callable[[Query, FeasibilityAnswer], None] | None = None
                         ) -> list[FeasibilityAnswer]:
        """Every answer, in the queries' order; one worker thread per replica that is up, each asking its own
        replica one question at a time from a shared queue. A question whose replica fails goes back to the
        queue; PlannerUnavailable when questions remain and every replica is down; any other error (Cancelled,
        a refused query) stops the batch and is raised once the questions in flight are back."""
        return self._many(queries, on_answer, lambda r, q: r.feasibility(*q))

    def certify_many(self, queries: Sequence[Query],
                     on_answer: Callable[[Query, FeasibilityAnswer], None] | None = None) -> list[FeasibilityAnswer]:
        """Every certification, in the queries' order, as feasibility_many (one in flight per replica that is up)."""
        return self._many(queries, on_answer, lambda r, q: certify_many(r, [q])[0])

    def _many(self, queries: Sequence[Query], on_answer: Callable[[Query, FeasibilityAnswer], None] | None,
              ask: Callable[[Replica, Query], FeasibilityAnswer]) -> list[FeasibilityAnswer]:
        """feasibility_many's work with `ask(replica, query)` as the question."""
        out: dict[int, FeasibilityAnswer] = {}  # query index -> answer
        todo = deque(range(len(queries)))
        stop: list[BaseException] = []
        lost: dict[int, PlannerUnavailable] = {}

        def worker(i: int) -> None:
            while True:
                with self._lock:
                    if stop or not todo:
                        return
                    k = todo.popleft()
                try:
                    a = ask(self.replicas[i], queries[k])
                except PlannerUnavailable as e:
                    lost[i] = e
                    self._failed(i)
                    with self._lock:
                        todo.appendleft(k)
                    return
                except BaseException as e:  # noqa: BLE001 - raised by the caller's thread below
                    with self._lock:
                        stop.append(e)
                    return
                self._answered(i)
                with self._lock:
                    out[k] = a
                    if on_answer is not None:
                        on_answer(queries[k], a)

        tried: set[int] = set()
        while todo and not stop:
            use = [i for i in self._usable() if i not in tried] or [i for i in self._order() if i not in tried][:1]
            if not use:
                if len(self.replicas) == 1:  # one planner: its own words
                    raise lost[0]
                raise PlannerUnavailable(f"no replica answered {len(todo)} of {len(queries)} feasibility "
                                         f"questions ({self.summary()})")
            if len(use) == 1:
                worker(use[0])
            else:
                threads = [threading.Thread(target=worker, args=(i,), daemon=True) for i in use]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join()
            tried.update(i for i in use if i in self.down)
        if stop:
            raise stop[0]
        return [out[k] for k in range(len(queries))]
