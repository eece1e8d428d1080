"""Policies LRND, H-LRND, H-eG and the epsilon decay of Eq. 14; training parameters."""
import math
import random
from collections import Counter

import pytest
from qtree_reference import epsilon_greedy, h_lrnd, lrnd

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.policies import epsilon_schedule
from qtree_task_planner.learning.q_tree import Node
from relocation_common.config import ParameterError, node_section
from relocation_common.paths import config_file


def test_eq14_first_middle_last_episode():
    # eps_e = eps0 * (eps_min / eps0) ** (e / (E_max - 1)), E_max = 11 episodes e = 0..10
    assert epsilon_schedule(0, 11, 1.0, 1e-3) == pytest.approx(1.0)
    assert epsilon_schedule(5, 11, 1.0, 1e-3) == pytest.approx(math.sqrt(1e-3))  # 0.0316...
    assert epsilon_schedule(10, 11, 1.0, 1e-3) == pytest.approx(1e-3)
    assert epsilon_schedule(5, 11, 0.5, 0.005) == pytest.approx(0.05)
    assert epsilon_schedule(0, 1, 0.8, 1e-3) == 0.8


def test_lrnd_is_uniform_over_offered_and_ignores_the_target_heuristic():
    rng, node = random.Random(1), Node(0, (), 0)
    counts = Counter(lrnd(node, [0, 2, 5], 5, rng, 0.0) for _ in range(3000))
    assert set(counts) == {0, 2, 5} and min(counts.values()) > 850


def test_h_lrnd_tries_the_target_first_else_uniform():
    rng, node = random.Random(1), Node(0, (), 0)
    assert all(h_lrnd(node, [0, 1, 3], 3, rng, 1.0) == 3 for _ in range(50))
    counts = Counter(h_lrnd(node, [0, 1, 2], 3, rng, 1.0) for _ in range(3000))
    assert set(counts) == {0, 1, 2} and min(counts.values()) > 850


def test_epsilon_greedy_heuristic_greedy_ties_and_exploration():
    rng, node = random.Random(1), Node(0, (), 0)
    node.q.update({0: -0.3, 1: 42.0, 2: 41.0})
    assert epsilon_greedy(node, [0, 1, 2, 4], 4, rng, 1.0) == 4  # the target first, whatever epsilon
    assert all(epsilon_greedy(node, [0, 1, 2], 4, rng, 0.0) == 1 for _ in range(50))
    assert all(epsilon_greedy(node, [0, 2], 4, rng, 0.0) == 2 for _ in range(50))
    # an edge not yet in the tree counts 0: it beats a negative known edge; ties are broken at random
    counts = Counter(epsilon_greedy(node, [0, 3, 5], 4, rng, 0.0) for _ in range(2000))
    assert set(counts) == {3, 5} and min(counts.values()) > 850
    counts = Counter(epsilon_greedy(node, [0, 1, 2], 4, rng, 1.0) for _ in range(3000))
    assert set(counts) == {0, 1, 2} and min(counts.values()) > 850


def test_default_params_come_from_the_one_yaml():
    p = TrainingParams.defaults()
    section = node_section(config_file("task_planner.yaml"), "task_planner")
    assert p.to_dict() == {k: section[k] for k in TrainingParams.fields()}
    assert (p.policy, p.search, p.epsilon0, p.epsilon_min) == ("h-eg", "depth", 1.0, 0.001)
    assert p.replace(alpha=0.1, seed=None).alpha == 0.1 and p.replace(alpha=0.1).seed == p.seed


@pytest.mark.parametrize("change, match", [
    ({"alpha": 1.5}, r"alpha must be in \[0.0, 1.0\]"),
    ({"gamma": -0.1}, r"gamma must be in \[0.0, 1.0\]"),
    ({"epsilon0": 0.0}, "epsilon0"),
    ({"epsilon_min": 0.5, "epsilon0": 0.1}, "must not exceed"),
    ({"max_episodes": -1}, "max_episodes must be >= 1"),
    ({"max_steps": 0}, "max_steps must be >= 1"),
    ({"max_steps": 2.5}, "max_steps must be an integer"),
    ({"beta": -0.1}, "beta must be in"),
    ({"quiet_episodes": 0}, "quiet_episodes"),
    ({"seed": -3}, "seed must be >= 0"),
    ({"policy": "greedy"}, "policy must be one of"),
    ({"search": "dfs"}, "search must be one of"),
    ({"alpah": 0.5}, "unknown parameter"),
    ({"alpha": "0.5"}, "finite number"),
])
def test_bad_params_raise_a_clear_error(change, match):
    with pytest.raises(ParameterError, match=match):
        TrainingParams.defaults().replace(**change)


def test_params_file_errors(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("task_planner: {ros__parameters: {alpha: 0.5}}\n")
    with pytest.raises(ParameterError, match="missing parameter"):
        TrainingParams.from_yaml(f)
    f.write_text("task_planner: [\n")
    with pytest.raises(ParameterError, match="malformed YAML"):
        TrainingParams.from_yaml(f)
    f.write_text("other: {}\n")
    with pytest.raises(ParameterError, match="ros__parameters"):
        TrainingParams.from_yaml(f)
    d = TrainingParams.defaults().to_dict()
    d["alpah"] = 0.5  # a typo: neither a training parameter nor one of the node's own
    import yaml
    f.write_text(yaml.safe_dump({"task_planner": {"ros__parameters": d}}))
    with pytest.raises(ParameterError, match="unknown parameter"):
        TrainingParams.from_yaml(f)
    assert TrainingParams.from_yaml(f, ignore_unknown=True) == TrainingParams.defaults()
