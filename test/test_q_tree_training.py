"""Training: breadth vs depth, pruning, both termination criteria, determinism, metrics, callback, and the
Q-Tree against the exact optimum on random small instances."""
import random

import pytest
import qtree_reference
from hypothesis import given, settings
from hypothesis import strategies as st
from qtree_reference import reference_train

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search.exact import solve
from relocation_common.feasibility import Label
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

SC5 = load_scenario(scenarios_dir() / "blocking_5.yaml")
SC10 = load_scenario(scenarios_dir() / "blocking_10.yaml")
BASE = TrainingParams.defaults()


def params(**kw):
    return BASE.replace(**kw)


def feasible_sequence(oracle, seq, target):
    removed = frozenset()
    for o in seq:
        label = oracle.feasibility(o, removed).label
        if label != (Label.TARGET if o == target else Label.OBSTACLE):
            return False
        removed |= {o}
    return seq[-1] == target


def episodes_of(sc, p):
    seen = []
    r = train(sc, BlockingOracle(sc), p, callback=seen.append, callback_every=1)
    return r, seen


def test_breadth_ends_at_the_first_unfeasible_action_depth_goes_on():
    p = params(policy="h-lrnd", max_episodes=30, beta=0.0)
    rb, eb = episodes_of(SC5, p.replace(search="breadth"))
    rd, ed = episodes_of(SC5, p.replace(search="depth"))
    # episode 1: the target is tried first at s_H and is blocked
    assert eb[0].steps == 1 and not eb[0].reached_target and eb[0].mp_q == 1
    assert ed[0].steps > 1 and ed[0].reached_target  # depth keeps choosing from the same node
    # breadth: every episode that did not reach the target stopped at its first unfeasible action
    assert all(s.reached_target or s.steps <= 5 for s in eb)
    assert rd.mp_q > rb.mp_q


def test_pruned_actions_are_never_chosen_again(monkeypatch):
    chosen_pruned = []
    original = qtree_reference.step

    def spy(tree, node, a):
        if node.label.get(a) == Label.UNFEASIBLE:
            chosen_pruned.append((node.seq, a))
        return original(tree, node, a)

    monkeypatch.setattr(qtree_reference, "step", spy)
    for policy in ("lrnd", "h-lrnd", "h-eg"):
        for search in ("breadth", "depth"):  # the reference loop (the engine equals it: test_q_tree_equivalence)
            r = reference_train(SC10, BlockingOracle(SC10), params(policy=policy, search=search, max_episodes=300))
            assert r["tree"].mp_q == r["tree"].n_edges
    assert chosen_pruned == []


def test_termination_at_e_max():
    r = train(SC5, BlockingOracle(SC5), params(policy="lrnd", max_episodes=40, beta=0.0))
    assert r.episodes == r.e_ss == 40 and not r.converged and len(r.q_sum_history) == 40


def test_termination_by_eq16_after_quiet_episodes():
    r = train(SC5, BlockingOracle(SC5), params(beta=1e9, quiet_episodes=3))
    assert r.converged and r.episodes == r.e_ss == 3
    p = params(beta=0.01, quiet_episodes=7)
    r = train(SC10, BlockingOracle(SC10), p)
    h = [0.0] + r.q_sum_history
    quiet = [abs(h[i] - h[i - 1]) <= p.beta for i in range(1, len(h))]
    assert r.converged and r.episodes < p.max_episodes
    assert all(quiet[-7:]) and not quiet[-8]  # stopped at the first run of 7 quiet episodes
    assert not any(all(quiet[i:i + 7]) for i in range(len(quiet) - 7))


def test_same_seed_same_result_other_seed_differs():
    p = params(max_episodes=300)
    a = train(SC10, BlockingOracle(SC10), p)
    b = train(SC10, BlockingOracle(SC10), p)
    assert a == b and a.q_sum_history == b.q_sum_history
    others = [train(SC10, BlockingOracle(SC10), p.replace(seed=s)).q_sum_history for s in (1, 2, 3)]
    assert any(h != a.q_sum_history for h in others)


def test_result_metrics_are_consistent():
    oracle = BlockingOracle(SC10)
    opt = solve(SC10, oracle).total_weight
    r = train(SC10, oracle, params(max_episodes=1500), optimal_weight=opt)
    assert r.found and feasible_sequence(oracle, r.sequence, "T")
    assert r.total_weight == pytest.approx(sum(SC10.weights[o] for o in r.sequence[:-1]))
    assert r.mp_q == r.tree_edges >= r.planner_calls > 0
    assert r.tree.q_abs_sum() == pytest.approx(r.q_sum_history[-1])
    assert r.e_1st is not None and 1 <= r.e_1st <= r.episodes
    d = r.to_dict()
    assert d["MP_q"] == r.mp_q and d["E_ss"] == r.e_ss and d["sequence"] == list(r.sequence)


def test_e_1st_is_the_first_episode_with_an_optimal_greedy_sequence():
    # LRND ignores epsilon, so a shorter run repeats the first episodes of a longer one exactly
    oracle = BlockingOracle(SC10)
    opt = solve(SC10, oracle).total_weight
    p = params(policy="lrnd", search="breadth", max_episodes=3000, beta=0.0)
    r = train(SC10, oracle, p, optimal_weight=opt)
    assert r.e_1st is not None and r.e_1st > 1
    at = train(SC10, oracle, p.replace(max_episodes=r.e_1st))
    before = train(SC10, oracle, p.replace(max_episodes=r.e_1st - 1))
    assert at.total_weight == pytest.approx(opt)
    assert before.total_weight is None or before.total_weight > opt + 1e-9


def test_shared_cache_counts_only_new_real_calls():
    cache = CachedOracle(BlockingOracle(SC10))
    p = params(max_episodes=200)
    first = train(SC10, cache, p)
    again = train(SC10, cache, p)
    assert first.planner_calls > 0 and again.planner_calls == 0 and again.mp_q == first.mp_q


def test_callback_false_cancels():
    r = train(SC10, BlockingOracle(SC10), params(), callback=lambda s: s.episode < 7, callback_every=1)
    assert r.cancelled and r.episodes == 7 and not r.converged
    seen = []
    r = train(SC10, BlockingOracle(SC10), params(), callback=lambda s: seen.append(s.episode) or s.episode < 7,
              callback_every=5)  # the engine runs 5 episodes between callbacks
    assert r.cancelled and r.episodes == 10 and seen == [5, 10]


def test_max_steps_bounds_each_episode():
    _, eps = episodes_of(SC10, params(policy="lrnd", search="depth", max_steps=2, max_episodes=50, beta=0.0))
    assert max(s.steps for s in eps) == 2


def random_blocking(seed, n):
    rnd = random.Random(seed)
    obstacles = tuple(f"o{i}" for i in range(n))
    weights = {o: rnd.choice([0.1, 0.2, 0.35, 0.5, 0.8, 1.0]) for o in obstacles}
    # a DAG: each object may be blocked by objects with lower index (the target by any)
    blocking = {o: rnd.sample(obstacles[:i], rnd.randint(0, min(i, 2))) for i, o in enumerate(obstacles)}
    blocking["T"] = rnd.sample(obstacles, rnd.randint(1, min(n, 3)))
    return RelocationProblem(obstacles, weights, "T"), BlockingOracle.from_relation(blocking, "T", obstacles + ("T",))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(1, 6), policy=st.sampled_from(["lrnd", "h-lrnd", "h-eg"]),
       search=st.sampled_from(["breadth", "depth"]))
def test_q_tree_never_beats_the_exact_optimum_and_returns_feasible_sequences(seed, n, policy, search):
    problem, oracle = random_blocking(seed, n)
    opt = solve(problem, oracle)
    r = train(problem, oracle, params(policy=policy, search=search, max_episodes=400, seed=seed % 1000))
    assert opt.found  # a DAG always frees the target
    if r.found:
        assert feasible_sequence(oracle, r.sequence, "T")
        assert r.total_weight >= opt.total_weight - 1e-9


def test_a_slow_planner_ends_a_batch_early_for_the_callback():
    """With a slow oracle the engine returns after the episode in which an answer came later than CALLBACK_S
    into the batch, so progress and cancel are not held for callback_every episodes; the result is unchanged."""
    import time as _time

    class Slow(BlockingOracle):
        def feasibility(self, object_id, removed):
            _time.sleep(0.02)
            return super().feasibility(object_id, removed)

    p = params(policy="lrnd", search="depth", max_episodes=100, beta=0.0)
    seen = []
    r = train(SC5, Slow(SC5), p, callback=lambda s: seen.append(s.episode), callback_every=1000)
    assert 1 < len(seen) < 100 and seen[-1] == 100 and seen == sorted(set(seen))
    assert r == train(SC5, BlockingOracle(SC5), p)
