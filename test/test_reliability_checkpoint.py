"""Q-Tree checkpoints (docs/reliability.md, section 1): atomic save, validated load, and a resumed training equal to an
uninterrupted one with the same seed (blocking_10, BlockingOracle), after a periodic checkpoint, after a restart from
disk, and after the planner died in the middle of an episode."""
import hashlib
import json
import os

import pytest

from qtree_task_planner.learning.checkpoint import (
    Checkpoint,
    CheckpointError,
    load_checkpoint,
    problem_hash,
    save_checkpoint,
)
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.search.exact import solve
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

SC10 = load_scenario(scenarios_dir() / "blocking_10.yaml")
PROBLEM = RelocationProblem.from_scenario(SC10)
PARAMS = TrainingParams.defaults().replace(seed=11)
OPT = solve(SC10, BlockingOracle(SC10)).total_weight


class PlannerDied(RuntimeError):
    pass


class DyingOracle:
    """BlockingOracle that raises once `after` calls were answered (a planner killed mid-training)."""

    def __init__(self, after):
        self.inner, self.after, self.calls = BlockingOracle(SC10), after, 0

    def feasibility(self, object_id, removed):
        if self.calls >= self.after:
            raise PlannerDied("feasibility service gone")
        self.calls += 1
        return self.inner.feasibility(object_id, removed)


def _same_run(a, b):
    assert a.sequence == b.sequence and a.total_weight == b.total_weight
    assert (a.episodes, a.e_ss, a.e_1st, a.converged, a.mp_q, a.planner_calls) == \
        (b.episodes, b.e_ss, b.e_1st, b.converged, b.mp_q, b.planner_calls)
    assert a.q_sum_history == b.q_sum_history  # bit for bit
    assert (a.tree_nodes, a.tree_edges) == (b.tree_nodes, b.tree_edges)
    assert a.tree.to_state() == b.tree.to_state()


@pytest.fixture(scope="module")
def uninterrupted():
    saved = []
    r = train(SC10, BlockingOracle(SC10), PARAMS, optimal_weight=OPT, checkpoint_every=50, on_checkpoint=saved.append)
    plain = train(SC10, BlockingOracle(SC10), PARAMS, optimal_weight=OPT)
    _same_run(r, plain)  # checkpointing itself changes nothing
    assert r.episodes > 150 and r.converged
    return r, saved


def test_periodic_checkpoints_and_the_final_one(uninterrupted):
    r, saved = uninterrupted
    assert [c.episode for c in saved[:-1]] == list(range(50, r.episodes, 50))
    assert saved[-1].episode == r.episodes and saved[-1].reason == "final" and saved[-1].converged
    c = saved[2]
    assert len(c.q_sum_history) == c.episode == 150 and c.q_sum_history == r.q_sum_history[:150]
    assert c.tree["nodes"] and c.planner_calls == len(c.feasibility)
    assert c.problem_hash == problem_hash(PROBLEM)


def test_the_file_is_the_canonical_body(uninterrupted, tmp_path):
    """The payload is encoded once and written as it is: the file's bytes are the canonical JSON (sorted keys, no
    spaces) of {format, version, sha256 of the payload's canonical JSON, payload}, the format load_checkpoint reads."""
    ck = uninterrupted[1][2]
    payload = ck.to_payload()

    def canonical(x):
        return json.dumps(x, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()

    body = {"format": "qtree-checkpoint", "version": 1, "sha256": hashlib.sha256(canonical(payload)).hexdigest(),
            "payload": payload}
    assert save_checkpoint(ck, tmp_path / "ck.json").read_bytes() == canonical(body)


def test_resume_from_disk_equals_the_uninterrupted_run(uninterrupted, tmp_path):
    r, saved = uninterrupted
    path = save_checkpoint(saved[1], tmp_path / "ck.json")  # episode 100
    ck = load_checkpoint(path)
    assert ck.to_payload() == saved[1].to_payload()
    resumed = train(SC10, BlockingOracle(SC10), PARAMS, optimal_weight=OPT, resume=ck)
    _same_run(resumed, r)
    # a fresh cache: the stored answers are reused, only the new questions reach the planner
    cache = CachedOracle(BlockingOracle(SC10))
    train(SC10, cache, PARAMS, optimal_weight=OPT, resume=ck)
    assert cache.calls == r.planner_calls - ck.planner_calls


def test_resume_from_the_final_checkpoint_trains_no_more(uninterrupted):
    r, saved = uninterrupted
    cache = CachedOracle(BlockingOracle(SC10))
    again = train(SC10, cache, PARAMS, optimal_weight=OPT, resume=saved[-1])
    _same_run(again, r)
    assert cache.calls == 0


@pytest.mark.parametrize("after", [1, 37, 150])
def test_planner_dies_mid_episode_then_resume_equals_uninterrupted(uninterrupted, after, tmp_path):
    r, _ = uninterrupted
    got = []
    cache = CachedOracle(DyingOracle(after))
    with pytest.raises(PlannerDied):
        train(SC10, cache, PARAMS, optimal_weight=OPT, checkpoint_every=1000, on_checkpoint=got.append)
    ck = got[-1]
    assert ck.reason.startswith("interrupted") and ck.episode < r.episodes
    assert len(ck.feasibility) == after  # every answer the planner gave is kept, also those of the lost episode
    assert ck.tree == _tree_after(ck.episode)  # the interrupted episode was rolled back
    path = save_checkpoint(ck, tmp_path / "ck.json")
    cache2 = CachedOracle(BlockingOracle(SC10))
    resumed = train(SC10, cache2, PARAMS, optimal_weight=OPT, resume=load_checkpoint(path))
    _same_run(resumed, r)
    assert cache2.calls == r.planner_calls - after  # nothing asked twice


def _tree_after(episodes):
    got = []
    train(SC10, BlockingOracle(SC10), PARAMS.replace(max_episodes=PARAMS.max_episodes), optimal_weight=OPT,
          checkpoint_every=1, on_checkpoint=got.append, callback=lambda s: s.episode < episodes)
    return got[-1].tree if episodes else {"nodes": [{"seq": [], "edges": []}], "mp_q": 0, "q_sum": 0.0}


def test_cancel_writes_a_resumable_checkpoint(uninterrupted):
    r, _ = uninterrupted
    got = []
    first = train(SC10, BlockingOracle(SC10), PARAMS, optimal_weight=OPT, on_checkpoint=got.append,
                  callback=lambda s: s.episode < 60)
    assert first.cancelled and got[-1].reason == "cancelled" and got[-1].episode == 60
    _same_run(train(SC10, BlockingOracle(SC10), PARAMS, optimal_weight=OPT, resume=got[-1]), r)


# -- refusals: corrupt, truncated, other version, other problem or params ---------------------------------------
@pytest.fixture
def ck_file(uninterrupted, tmp_path):
    return save_checkpoint(uninterrupted[1][0], tmp_path / "ck.json")


def _rewrite(path, fn):
    body = json.loads(path.read_text())
    fn(body)
    path.write_text(json.dumps(body))


@pytest.mark.parametrize("damage, words", [
    (lambda p: p.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2]), "malformed JSON"),
    (lambda p: p.write_bytes(b"\x00\xff garbage"), "malformed JSON"),
    (lambda p: p.write_text("[1, 2]"), "not a Q-Tree checkpoint"),
    (lambda p: _rewrite(p, lambda b: b.update(version=99)), "version 99"),
    (lambda p: _rewrite(p, lambda b: b["payload"]["tree"]["nodes"][0]["edges"][0].__setitem__(2, 5.0)),
     "checksum mismatch"),
    (lambda p: _rewrite(p, lambda b: b["payload"].update(episode=3)), "checksum mismatch"),
    (lambda p: p.unlink(), "cannot read"),
])
def test_corrupt_checkpoints_are_refused_with_a_clear_error(ck_file, damage, words):
    damage(ck_file)
    with pytest.raises(CheckpointError, match=words) as e:
        load_checkpoint(ck_file)
    assert str(ck_file) in str(e.value)


def test_inconsistent_contents_with_a_valid_checksum_are_refused(uninterrupted, tmp_path):
    import copy
    ck = copy.deepcopy(uninterrupted[1][0])
    ck.tree["nodes"][1]["seq"] = [0, 0]  # not a sequence of distinct obstacles
    path = save_checkpoint(ck, tmp_path / "ck.json")
    loaded = load_checkpoint(path)
    with pytest.raises(CheckpointError, match="inconsistent"):
        train(SC10, BlockingOracle(SC10), PARAMS, resume=loaded)
    ck = copy.deepcopy(uninterrupted[1][0])
    ck.q_sum_history.pop()
    with pytest.raises(CheckpointError, match="inconsistent"):
        load_checkpoint(save_checkpoint(ck, tmp_path / "ck2.json"))


def test_checkpoint_for_another_problem_or_params_is_refused(ck_file):
    ck = load_checkpoint(ck_file)
    with pytest.raises(CheckpointError, match="other training parameters.*seed 11 != 12"):
        train(SC10, BlockingOracle(SC10), PARAMS.replace(seed=12), resume=ck)
    sc5 = load_scenario(scenarios_dir() / "blocking_5.yaml")
    with pytest.raises(CheckpointError, match="another scene"):
        train(sc5, BlockingOracle(sc5), PARAMS, resume=ck)
    heavier = RelocationProblem(PROBLEM.obstacles, {**PROBLEM.weights, PROBLEM.obstacles[0]: 0.99}, PROBLEM.target)
    assert problem_hash(heavier) != problem_hash(PROBLEM)


def test_save_is_atomic_a_failed_write_keeps_the_old_file(uninterrupted, tmp_path, monkeypatch):
    _, saved = uninterrupted
    path = save_checkpoint(saved[0], tmp_path / "ck.json")
    before = path.read_bytes()

    def boom(*a):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        save_checkpoint(saved[1], path)
    assert path.read_bytes() == before and load_checkpoint(path).episode == 50
    assert [p.name for p in tmp_path.iterdir()] == ["ck.json"]  # no temporary left behind
    monkeypatch.undo()
    save_checkpoint(saved[1], path)
    assert load_checkpoint(path).episode == 100


def test_checkpoint_round_trip_keeps_rng_and_counters(uninterrupted):
    c = uninterrupted[1][1]
    back = Checkpoint.from_payload(json.loads(json.dumps(c.to_payload())))
    assert back.rng_state == c.rng_state and back.epsilon == c.epsilon and back.quiet == c.quiet
    assert back.params == PARAMS and back.feasibility == c.feasibility


def test_blocker_sets_survive_a_checkpoint_on_disk(tmp_path):
    """The blocker A* (astar.py) needs an unfeasible answer's blockers to ask nothing twice after a resume: they
    are stored with the answers and come back from the file (answers without blockers keep the 3-field rows)."""
    cache = CachedOracle(BlockingOracle(SC10))
    asked = [(o, frozenset()) for o in SC10.ids]
    for o, s in asked:
        cache.feasibility(o, s)
    assert any(a.blockers for a in cache.table.values()) and any(not a.blockers for a in cache.table.values())
    ck = Checkpoint.initial(RelocationProblem.from_scenario(SC10), TrainingParams.defaults(), cache)
    back = Checkpoint.from_payload(json.loads(json.dumps(ck.to_payload())))
    fresh = CachedOracle(BlockingOracle(SC10))
    assert back.fill_cache(fresh) == len(asked)
    for key in cache.table:
        assert fresh.table[key].label == cache.table[key].label
        assert fresh.table[key].blockers == cache.table[key].blockers, key
