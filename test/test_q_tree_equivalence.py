"""The fast Q-Tree training reproduces the reference implementation bit for bit.

test/data/qtree_reference.json was recorded with the pure-dict implementation of q_tree.py / policies.py /
training.py as it was before the speed-up (commit 54e462d), by running this file as a script:
    PYTHONPATH=. .venv/bin/python test/test_q_tree_equivalence.py --record
Each case is a full TrainingParams (explicit, independent of config/task_planner.yaml) on a scene with a
deterministic oracle (blocking_5/10/15 with BlockingOracle; scenario1_5 and scenario2_10 with the real planner's
answers of the committed caches it was recorded with, kept in test/data/qtree_reference_tables/: the planner's
parameters have changed since, and with them data/feasibility/). Compared exactly: sequence, total_weight, episodes,
converged, E_ss, MP_q, planner calls, E_1st, tree size, the Eq. 15 history (every float, by its IEEE bits) and the
whole tree (QTree.to_state(), every Q by its bits). The one engine (the C kernel, qtree_task_planner/learning/kernel.py,
through training.train) is checked against it in one batch, in batches between callbacks and with checkpoints; the
reference loop (the policies and `step` of test/qtree_reference.py) is checked against it too.
"""
from __future__ import annotations

import hashlib
import json
import struct
import sys
from pathlib import Path

import pytest
from qtree_reference import reference_train

from qtree_task_planner.learning import kernel
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search import exact
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "test" / "data" / "qtree_reference.json"
TABLES = ROOT / "test" / "data" / "qtree_reference_tables"  # the committed feasibility caches of the recording
ALGORITHMS = [(p, s) for p in ("lrnd", "h-lrnd", "h-eg") for s in ("breadth", "depth")]
BASE = dict(alpha=0.5, gamma=1.0, epsilon0=1.0, epsilon_min=1e-3, max_episodes=1500, max_steps=100, beta=0.01,
            quiet_episodes=20)


def float_digest(values) -> str:
    """SHA-256 of the IEEE-754 bits of a float sequence (bit-exact comparison of long histories)."""
    return hashlib.sha256(struct.pack(f"<{len(values)}d", *values)).hexdigest()


def tree_digest(state: dict) -> str:
    """SHA-256 of QTree.to_state(): node sequences, edges in creation order (action, label, Q bits), MP_q and
    the incremental Eq. 15 sum."""
    h = hashlib.sha256()
    for n in state["nodes"]:
        h.update(repr(n["seq"]).encode())
        for a, lab, q in n["edges"]:
            h.update(struct.pack("<iid", a, lab, q))
    h.update(struct.pack("<id", state["mp_q"], state["q_sum"]))
    return h.hexdigest()


def cases() -> list[dict]:
    out = []
    for scene in ("blocking_5", "blocking_10", "blocking_15"):
        for policy, search in ALGORITHMS:
            for seed in (0, 1, 2):
                out.append(dict(scene=scene, params=BASE | dict(policy=policy, search=search, seed=seed)))
        # other (alpha, gamma), no early stop, short episodes (I_max), tiny E_max
        for policy, search in ALGORITHMS:
            out.append(dict(scene=scene, params=BASE | dict(policy=policy, search=search, seed=7, alpha=1.0,
                                                              gamma=0.1, beta=0.0, max_episodes=700)))
            out.append(dict(scene=scene, params=BASE | dict(policy=policy, search=search, seed=3, alpha=0.3,
                                                              gamma=0.9, max_steps=3, max_episodes=400)))
    for scene, e_max in (("scenario1_5", 10_000), ("scenario2_10", 3000)):
        for policy, search in ALGORITHMS:
            for seed, (alpha, gamma) in ((0, (0.3, 0.9)), (1, (1.0, 0.1)), (2, (0.5, 0.5))):
                out.append(dict(scene=scene, params=BASE | dict(policy=policy, search=search, seed=seed,
                                                                  alpha=alpha, gamma=gamma, max_episodes=e_max)))
    return out


_SCENES: dict = {}


def setting(scene: str):
    """(problem, oracle, optimal weight) of a scene; the scenario* ones from the committed feasibility cache."""
    if scene not in _SCENES:
        sc = load_scenario(scenarios_dir() / f"{scene}.yaml")
        if scene.startswith("blocking"):
            oracle = BlockingOracle(sc)
        else:  # the tables the fixture was recorded with, whatever the planner's parameters are today
            from relocation_app.evaluation.feasibility_cache import PlannerOracle, load_table
            oracle = PlannerOracle(sc, None, load_table(TABLES / f"{scene}.json"))
        problem = RelocationProblem.from_scenario(sc)
        _SCENES[scene] = (problem, oracle, exact.solve(problem, oracle).total_weight)
    return _SCENES[scene]


def run_case(case: dict, **kw) -> dict:
    problem, oracle, opt = setting(case["scene"])
    r = train(problem, oracle, TrainingParams(**case["params"]), optimal_weight=opt, **kw)
    return {"sequence": list(r.sequence) if r.sequence is not None else None,
            "total_weight": None if r.total_weight is None else r.total_weight.hex(),
            "episodes": r.episodes, "converged": r.converged, "e_ss": r.e_ss, "mp_q": r.mp_q,
            "planner_calls": r.planner_calls, "e_1st": r.e_1st, "tree_nodes": r.tree_nodes,
            "tree_edges": r.tree_edges, "q_sum_len": len(r.q_sum_history),
            "q_sum_last": r.q_sum_history[-1].hex() if r.q_sum_history else None,
            "q_sum_history": float_digest(r.q_sum_history), "tree": tree_digest(r.tree.to_state())}


def case_id(case: dict) -> str:
    p = case["params"]
    return (f"{case['scene']}-{p['policy']}-{p['search']}-s{p['seed']}-a{p['alpha']}-g{p['gamma']}"
            f"-E{p['max_episodes']}-I{p['max_steps']}-b{p['beta']}")


def load_fixture() -> list[dict]:
    return json.loads(FIXTURE.read_text())["cases"]


@pytest.mark.parametrize("case", load_fixture() if FIXTURE.exists() else [], ids=case_id)
def test_training_reproduces_the_reference_bit_for_bit(case):
    assert run_case(case) == case["result"]


CASES = load_fixture() if FIXTURE.exists() else []


@pytest.mark.parametrize("case", CASES[::3], ids=case_id)
def test_training_with_callbacks_reproduces_the_reference(case):
    seen = []
    assert run_case(case, callback=seen.append, callback_every=7) == case["result"]  # batches of 7 episodes
    episodes = [s.episode for s in seen]
    assert episodes[-1] == case["result"]["episodes"] and episodes == sorted(set(episodes))
    # every 7th episode reported; a batch that asked the oracle for over CALLBACK_S (a loaded machine) may end
    # early with one more report (training.train's docstring), never fewer
    assert set(range(7, episodes[-1], 7)) <= set(episodes)


@pytest.mark.parametrize("case", CASES[::7], ids=case_id)
def test_training_with_checkpoints_reproduces_the_reference(case):
    final = []
    assert run_case(case, on_checkpoint=final.append) == case["result"]
    assert [c.reason for c in final] == ["final"]


@pytest.mark.parametrize("case", CASES[::11], ids=case_id)
def test_the_reference_loop_is_the_recorded_oracle(case):
    """The reference (the policies and `step` of test/qtree_reference.py) still reproduces the recording."""
    problem, oracle, opt = setting(case["scene"])
    ref = reference_train(problem, oracle, TrainingParams(**case["params"]), optimal_weight=opt)
    want = case["result"]
    assert (ref["episodes"], ref["converged"], ref["e_1st"]) == (want["episodes"], want["converged"], want["e_1st"])
    assert float_digest(ref["history"]) == want["q_sum_history"]
    assert tree_digest(ref["tree"].to_state()) == want["tree"]


def test_kernel_is_built_and_used():
    assert kernel.available(), kernel.build_error
    problem, oracle, opt = setting("blocking_10")
    r = train(problem, oracle, TrainingParams(**(BASE | dict(policy="lrnd", search="depth", seed=0))))
    assert isinstance(r.tree, kernel.KernelTree)
    # the tree is exported on first use, and agrees with the kernel's counts
    assert r.tree._py_nodes is None
    seq_before = r.tree.best_sequence()
    assert r.tree_nodes == len(r.tree.nodes) and r.tree_edges == r.tree.n_edges == r.mp_q
    assert r.tree.best_sequence() == seq_before == r.sequence
    assert r.tree.q_abs_sum() == pytest.approx(r.q_sum_history[-1])
    assert "digraph" in r.tree.to_dot()


@pytest.mark.parametrize("policy,search", ALGORITHMS)
def test_kernel_asks_the_cache_exactly_like_the_reference(policy, search):
    from qtree_task_planner.oracles import CachedOracle
    sc = load_scenario(scenarios_dir() / "blocking_15.yaml")
    p = TrainingParams(**(BASE | dict(policy=policy, search=search, seed=4, max_episodes=600)))
    cache = CachedOracle(BlockingOracle(sc))
    r = train(sc, cache, p)
    ref = reference_train(sc, BlockingOracle(sc), p)["cache"]
    assert (cache.calls, cache.queries, list(cache.table)) == (ref.calls, ref.queries, list(ref.table))
    assert r.planner_calls == cache.calls and cache.queries == r.mp_q  # one cache query per new tree edge (MP_q)


def test_kernel_propagates_oracle_errors():
    from relocation_common.feasibility import FeasibilityAnswer, Label
    problem, oracle, _ = setting("blocking_10")

    class Dies:
        def __init__(self):
            self.n = 0

        def feasibility(self, object_id, removed):
            self.n += 1
            if self.n > 30:
                raise ConnectionError("planner gone")
            return oracle.feasibility(object_id, removed)

    class Liar:
        def feasibility(self, object_id, removed):
            return FeasibilityAnswer(Label.TARGET)

    p = TrainingParams(**(BASE | dict(policy="lrnd", search="depth", seed=0)))
    with pytest.raises(ConnectionError, match="planner gone"):
        train(problem, Dies(), p)
    with pytest.raises(ValueError, match="TARGET is for the target only"):
        train(problem, Liar(), p)


def test_fixture_covers_every_algorithm_and_scene():
    fixture = load_fixture()
    assert {(c["scene"], c["params"]["policy"], c["params"]["search"]) for c in fixture} == {
        (s, p, q) for s in ("blocking_5", "blocking_10", "blocking_15", "scenario1_5", "scenario2_10")
        for p, q in ALGORITHMS}
    # not a degenerate fixture: some runs converge, some hit E_max, E_1st found and not found, long histories
    results = [c["result"] for c in fixture]
    assert any(r["converged"] for r in results) and any(not r["converged"] for r in results)
    assert any(r["e_1st"] is None for r in results) and any(r["e_1st"] for r in results)
    assert max(r["episodes"] for r in results) >= 3000


def record() -> None:
    out = []
    for case in cases():
        out.append(case | {"result": run_case(case)})
        print(case_id(case), out[-1]["result"]["episodes"], flush=True)
    FIXTURE.parent.mkdir(parents=True, exist_ok=True)
    FIXTURE.write_text(json.dumps({"recorded_with": "q_tree.py/policies.py/training.py before the speed-up "
                                                    "(commit 54e462d)", "cases": out}, indent=1) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        sys.exit("usage: test_q_tree_equivalence.py --record   (overwrites test/data/qtree_reference.json)")
    record()
