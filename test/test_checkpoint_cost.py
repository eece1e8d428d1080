"""Checkpoints read and encode only what changed (qtree_task_planner.learning.kernel.KernelTree.to_state,
learning.checkpoint's encoding): every state and every file is the one a whole export and a whole encoding give, after
periodic checkpoints, an episode rolled back (a planner lost mid-episode) and a failed certification's relabelling."""
import json
from types import SimpleNamespace

import pytest

from qtree_task_planner.learning import checkpoint as ckmod
from qtree_task_planner.learning.kernel import KernelTree
from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.q_tree import QTree
from qtree_task_planner.learning.training import train
from qtree_task_planner.oracles import BlockingOracle, CachedOracle
from relocation_common.paths import scenarios_dir
from relocation_common.scenario import load_scenario

SC15 = load_scenario(scenarios_dir() / "blocking_15.yaml")
PARAMS = TrainingParams.defaults().replace(seed=3, max_episodes=1500, beta=0.0, search="depth")


def whole(tree: KernelTree) -> dict:
    """QTree.to_state of the tree's Python nodes, exported afresh from the kernel (the whole tree read again)."""
    return QTree.to_state(SimpleNamespace(nodes=tree._export(), mp_q=tree.mp_q, q_sum=tree.q_sum))


def bits(state: dict) -> str:
    return json.dumps(state, sort_keys=True)  # floats by repr: Q compared bit for bit


@pytest.fixture
def checked(monkeypatch):
    """KernelTree.to_state compared with the whole export at every call; save_checkpoint's file compared with the
    whole canonical encoding of its payload."""
    seen = {"states": 0, "files": 0}
    to_state, save = KernelTree.to_state, ckmod.save_checkpoint

    def to_state_checked(self):
        got = to_state(self)
        assert bits(got) == bits(whole(self)), f"state {seen['states']} differs from the whole export"
        seen["states"] += 1
        return got

    def save_checked(ck, path):
        out = save(ck, path)
        payload = ckmod._canonical(ck.to_payload())
        assert out.read_bytes() == ckmod._canonical_body(payload), f"file {seen['files']} is not the whole encoding"
        seen["files"] += 1
        return out

    monkeypatch.setattr(KernelTree, "to_state", to_state_checked)
    return seen, save_checked


def test_periodic_checkpoints_are_the_whole_tree(checked, tmp_path):
    seen, save = checked
    r = train(SC15, BlockingOracle(SC15), PARAMS, checkpoint_every=7,
              on_checkpoint=lambda ck: save(ck, tmp_path / "ck.json"))
    assert r.episodes > 300 and seen["states"] >= r.episodes // 7 and seen["files"] == seen["states"]
    assert bits(r.tree.to_state()) == bits(whole(r.tree))


class Dying(BlockingOracle):
    """Raises at the `after`-th call (a planner lost in the middle of an episode: the kernel rolls it back)."""

    def __init__(self, scenario, after):
        super().__init__(scenario)
        self.after, self.calls = after, 0

    def feasibility(self, object_id, removed):
        self.calls += 1
        if self.calls >= self.after:
            raise RuntimeError("planner gone")
        return super().feasibility(object_id, removed)


def test_a_rolled_back_episode_and_a_relabelled_edge(checked, tmp_path):
    seen, save = checked
    kept = []
    with pytest.raises(RuntimeError, match="planner gone"):
        train(SC15, CachedOracle(Dying(SC15, 400)), PARAMS, checkpoint_every=3,
              on_checkpoint=lambda ck: kept.append(save(ck, tmp_path / "ck.json")))
    assert kept and seen["states"] > 3
    r = train(SC15, BlockingOracle(SC15), PARAMS.replace(max_episodes=300))
    tree = r.tree
    tree.to_state()
    seq = tree.best_sequence()
    assert seq is not None and len(seq) > 1
    assert tree.relabel(seq[1], frozenset(seq[:1])) >= 1  # a certification failed: its subtree dropped, nodes moved
    assert bits(tree.to_state()) == bits(whole(tree))
