"""ReplicaOracle (qtree_task_planner.executive.replicas): several feasibility questions in flight over planner replicas,
failover when one dies, and the exact planners asking through it (same optimum as with one planner)."""
import random
import threading
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_astar import lane_instance

from qtree_task_planner.executive.outage import Cancelled, PlannerUnavailable
from qtree_task_planner.executive.replicas import ReplicaOracle
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.search import astar, exact
from relocation_common.feasibility import Label


class Replica:
    """A planner process as the task planner sees it: answers from `oracle` after `delay` s; after `dies_after`
    answers it is gone (PlannerUnavailable, as ServiceOracle raises for a vanished service)."""

    def __init__(self, oracle, name, delay=0.0, dies_after=None):
        self.oracle, self.name, self.delay, self.dies_after = oracle, name, delay, dies_after
        self.asked, self.last_ok, self.busy, self.most_busy = [], 0.0, 0, 0
        self._lock = threading.Lock()

    @property
    def dead(self):
        return self.dies_after is not None and len(self.asked) >= self.dies_after

    def ready(self, timeout):
        return not self.dead

    def feasibility(self, o, removed):
        if self.dead:
            raise PlannerUnavailable(f"{self.name} went away")
        with self._lock:
            self.busy += 1
            self.most_busy = max(self.most_busy, self.busy)
        time.sleep(self.delay)
        with self._lock:
            self.busy -= 1
        self.asked.append((o, frozenset(removed)))
        self.last_ok = time.monotonic()
        return self.oracle.feasibility(o, removed)

    def lane_blockers(self, removed):
        if self.dead:
            raise PlannerUnavailable(f"{self.name} went away")
        return self.oracle.lane_blockers(removed)


def relation_oracle(seed=0, n=8):
    rnd = random.Random(seed)
    ids = [f"o{i}" for i in range(n)] + ["T"]
    return BlockingOracle.from_relation({o: rnd.sample([x for x in ids if x != o], rnd.randint(0, 2)) for o in ids},
                                        "T", ids), ids


def questions(ids, k=24, seed=1):
    rnd = random.Random(seed)
    return [(o, frozenset(rnd.sample([x for x in ids if x != o], rnd.randint(0, 3)))) for o in rnd.choices(ids, k=k)]


def test_many_questions_go_to_every_replica_at_once_and_come_back_in_order():
    truth, ids = relation_oracle()
    reps = [Replica(truth, "a", 0.01), Replica(truth, "b", 0.01)]
    oracle = ReplicaOracle(reps)
    qs = questions(ids)
    seen = []
    assert oracle.in_flight == 2
    got = oracle.feasibility_many(qs, lambda q, a: seen.append(q))
    assert [a.label for a in got] == [truth.feasibility(*q).label for q in qs]
    assert sorted(map(str, seen)) == sorted(map(str, qs))
    assert all(r.asked for r in reps) and sum(len(r.asked) for r in reps) == len(qs)
    assert oracle.answers == [len(reps[0].asked), len(reps[1].asked)]


def test_one_question_at_a_time_goes_to_the_first_replica_while_it_is_up():
    truth, ids = relation_oracle()
    reps = [Replica(truth, "a"), Replica(truth, "b")]
    oracle = ReplicaOracle(reps)
    for q in questions(ids, 10):
        oracle.feasibility(*q)
    assert len(reps[0].asked) == 10 and not reps[1].asked  # a sequential training sees one planner


def test_a_replica_that_dies_mid_batch_loses_no_question():
    truth, ids = relation_oracle()
    reps = [Replica(truth, "a", 0.005), Replica(truth, "b", 0.005, dies_after=3)]
    oracle = ReplicaOracle(reps)
    qs = questions(ids, 30)
    got = oracle.feasibility_many(qs)
    assert [a.label for a in got] == [truth.feasibility(*q).label for q in qs]
    assert len(reps[1].asked) == 3 and len(reps[0].asked) == 27
    assert 1 in oracle.down and oracle.in_flight == 1 and "(down)" in oracle.summary()


def test_the_first_replica_dying_hands_sequential_questions_to_the_next():
    truth, ids = relation_oracle()
    reps = [Replica(truth, "a", dies_after=2), Replica(truth, "b")]
    oracle = ReplicaOracle(reps, retry_after=60.0)
    for q in questions(ids, 6):
        oracle.feasibility(*q)
    assert len(reps[0].asked) == 2 and len(reps[1].asked) == 4
    assert oracle.lane_blockers(frozenset()) == truth.lane_blockers(frozenset())


def test_a_replica_down_is_asked_again_after_retry_after():
    truth, ids = relation_oracle()
    now = [0.0]
    reps = [Replica(truth, "a", dies_after=1), Replica(truth, "b")]
    oracle = ReplicaOracle(reps, retry_after=5.0, clock=lambda: now[0])
    qs = questions(ids, 4)
    oracle.feasibility(*qs[0])
    oracle.feasibility(*qs[1])  # a dies here: b answers
    reps[0].dies_after = None  # a restarted
    oracle.feasibility(*qs[2])
    assert len(reps[0].asked) == 1  # still resting
    now[0] = 6.0
    oracle.feasibility(*qs[3])
    assert len(reps[0].asked) == 2 and 0 not in oracle.down


def test_a_replica_that_keeps_failing_rests_longer_each_time():
    truth, ids = relation_oracle()
    now = [0.0]
    reps = [Replica(truth, "a", dies_after=0), Replica(truth, "b")]
    oracle = ReplicaOracle(reps, retry_after=5.0, max_rest=12.0, clock=lambda: now[0])
    tries = []
    for t in range(40):  # one question a second, a stays dead
        now[0] = float(t)
        calls = oracle.answers[1]
        oracle.feasibility(*questions(ids, 1, seed=t)[0])
        assert oracle.answers[1] == calls + 1
        if oracle.failures[0] > len(tries):
            tries.append(t)
    assert tries == [0, 5, 15, 27, 39]  # rests 5, 10, then max_rest 12


def test_all_replicas_gone_raise_planner_unavailable_and_keep_what_came_back():
    truth, ids = relation_oracle()
    reps = [Replica(truth, "a", 0.002, dies_after=4), Replica(truth, "b", 0.002, dies_after=5)]
    cache = CachedOracle(ReplicaOracle(reps))
    qs = list(dict.fromkeys(questions(ids, 40)))
    with pytest.raises(PlannerUnavailable, match="no replica answered"):
        cache.feasibility_many(qs)
    assert cache.calls == len(cache.table) == 9  # every answer given before the outage is kept
    with pytest.raises(PlannerUnavailable, match="a: a went away; b: b went away"):
        ReplicaOracle(reps).feasibility(*qs[-1])


def test_cancel_stops_a_batch():
    truth, ids = relation_oracle()

    class Cancelling(Replica):
        def feasibility(self, o, removed):
            if len(self.asked) >= 2:
                raise Cancelled("cancelled")
            return super().feasibility(o, removed)

    with pytest.raises(Cancelled):
        ReplicaOracle([Cancelling(truth, "a"), Cancelling(truth, "b")]).feasibility_many(questions(ids, 20))


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 10**9), n=st.integers(0, 7), mode=st.sampled_from(("exact", "answers", "uncertain")),
       p_fail=st.sampled_from([0.0, 0.15]), replicas=st.integers(2, 3))
def test_exact_planners_over_replicas_find_the_same_optimum(seed, n, mode, p_fail, replicas):
    """Uniform-cost search: the same sequence (its order of settling is unchanged, answers only come earlier);
    A*: the same optimal weight. Both ask at most `replicas` x the questions of one planner."""
    problem, truth = lane_instance(seed, n, mode, p_fail)
    one_ucs, one_astar = exact.solve(problem, truth), astar.solve(problem, truth)
    many = ReplicaOracle([Replica(truth, f"r{k}") for k in range(replicas)])
    ucs, ast = exact.solve(problem, many), astar.solve(problem, many)
    assert ucs.sequence == one_ucs.sequence and ucs.total_weight == one_ucs.total_weight
    assert ast.found == one_astar.found
    if ast.found:
        assert ast.total_weight == pytest.approx(one_astar.total_weight)
        removed = frozenset()
        for o in ast.sequence[:-1]:
            assert truth.truly(o, removed)
            removed |= {o}
    assert ucs.oracle_calls <= replicas * max(1, one_ucs.oracle_calls)
    assert ast.oracle_calls <= replicas * max(1, one_astar.oracle_calls)


def test_uniform_cost_keeps_every_replica_busy():
    problem, truth = lane_instance(3, 7, "answers", 0.0)
    reps = [Replica(truth, f"r{k}", 0.003) for k in range(2)]
    r = exact.solve(problem, ReplicaOracle(reps))
    assert r.found and all(rep.asked for rep in reps)
    assert max(rep.most_busy for rep in reps) == 1  # one question per replica at a time
    assert Label(truth.feasibility(*([problem.target, frozenset(r.sequence[:-1])])).label) == Label.TARGET
