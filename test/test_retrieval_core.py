"""qtree_task_planner.executive.retrieval: exact optimum then training through an oracle that goes away; execution
order."""
from qtree_task_planner.executive.outage import PlannerUnavailable
from qtree_task_planner.executive.retrieval import execute_sequence, solve_then_train, training_outcome
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.scenario import load_scenario

SC = load_scenario("blocking_5")
PARAMS = TrainingParams.defaults().replace(seed=1, max_episodes=200)


class Flaky:
    """The blocking relation, unavailable once at the given call."""

    def __init__(self, fail_at: int):
        self.inner, self.calls, self.fail_at = BlockingOracle(SC), 0, fail_at

    def feasibility(self, object_id, removed):
        self.calls += 1
        if self.calls == self.fail_at:
            raise PlannerUnavailable("gone")
        return self.inner.feasibility(object_id, removed)


def retry(fn):
    while True:
        try:
            return fn()
        except PlannerUnavailable:
            pass


def test_an_outage_during_the_exact_solve_keeps_the_answers_and_gives_the_same_result():
    problem = RelocationProblem.from_scenario(SC)
    kept = []
    flaky = Flaky(fail_at=3)
    optimum, r = solve_then_train(problem, CachedOracle(flaky), PARAMS, resume=None, until_planner=retry,
                                  keep=kept.append, on_episode=lambda s: True, checkpoint_every=1000)
    ref_opt, ref = solve_then_train(problem, CachedOracle(BlockingOracle(SC)), PARAMS, resume=None,
                                    until_planner=retry, keep=lambda ck: None, on_episode=lambda s: True,
                                    checkpoint_every=1000)
    assert kept and kept[0].reason.startswith("interrupted") and len(kept[0].feasibility) == 2
    assert optimum.sequence == ref_opt.sequence and r.sequence == ref.sequence and r.found


def test_no_training_when_the_exact_solve_proves_there_is_no_sequence():
    """T's lane needs b gone and b's needs T gone (a blocking cycle): the A* proves it in 0 planner calls, and the
    goal ends with its reason instead of training up to E_max (before: every episode asked in vain)."""
    problem = RelocationProblem(("a", "b"), {"a": 0.2, "b": 0.5}, "T")
    oracle = CachedOracle(BlockingOracle.from_relation({"T": {"b"}, "b": {"T"}}, "T", ("a", "b", "T")))
    optimum, r = solve_then_train(problem, oracle, PARAMS, resume=None, until_planner=retry, keep=lambda ck: None,
                                  on_episode=lambda s: True, checkpoint_every=1000)
    assert not optimum.found and "blocking cycle" in optimum.reason
    assert r.episodes == 0 and not r.found and not r.cancelled
    ok, message = training_outcome(r, optimum, execute=True)
    assert not ok and message.startswith("the target cannot be retrieved: no sequence with the actions side_grasp, "
                                         "top_grasp: blocking cycle"), message


def test_execution_stops_at_the_first_failure_and_on_cancel():
    calls = []

    def relocate(i, removed):
        calls.append((i, removed))
        return (i != "b", "gripper closed on nothing")

    ok, msg, done = execute_sequence(["a", "b", "T"], relocate, cancelled=lambda: False)
    assert not ok and "relocating 'b' failed: gripper closed on nothing" in msg and done == ["a"]
    assert calls == [("a", []), ("b", ["a"])]
    ok, msg, done = execute_sequence(["a", "T"], lambda i, r: (True, ""), cancelled=lambda: True)
    assert not ok and msg.startswith("cancelled") and done == []
    ok, msg, done = execute_sequence(["a", "T"], lambda i, r: (True, ""), cancelled=lambda: False)
    assert ok and "'T' retrieved after 1 relocations" in msg
