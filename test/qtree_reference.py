"""The reference Q-Tree training loop (paper Sect. 4.2), by the book: the policy function of policies.py picks
an action (Eq. 14 epsilon), QTree.step labels it (Eq. 11), rewards it (Eq. 13) and updates it (Eq. 7); Eq. 15
after each episode, the Eq. 16 stop, E_1st. The tests' oracle for the production engine (qtree_task_planner.kernel
through training.train): same seed, same tree, bit for bit."""
from __future__ import annotations

import random

from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.params import TrainingParams
from qtree_task_planner.policies import POLICY_FUNCTIONS, epsilon_schedule
from qtree_task_planner.problem import RelocationProblem
from qtree_task_planner.q_tree import QTree
from relocation_common.feasibility import Label

WEIGHT_TOL = 1e-9


def reference_episode(tree: QTree, policy, rng: random.Random, epsilon: float, depth: bool,
                      i_max: int) -> tuple[int, bool]:
    """One episode from s_H; returns (steps, reached the target)."""
    node, steps = tree.root, 0
    while steps < i_max:
        offered = node.offered(tree.n_objects)
        if not offered:
            break
        a = policy(node, offered, tree.target, rng, epsilon)
        steps += 1
        label, nxt = tree.step(node, a)
        if label == Label.TARGET:
            return steps, True
        if label == Label.UNFEASIBLE:
            if depth:
                continue
            break
        node = nxt
    return steps, False


def reference_train(problem, oracle, params: TrainingParams, optimal_weight: float | None = None) -> dict:
    """The whole training: {tree, episodes, converged, e_1st, history, cache}."""
    if not isinstance(problem, RelocationProblem):
        problem = RelocationProblem.from_scenario(problem)
    cache = oracle if isinstance(oracle, CachedOracle) else CachedOracle(oracle)
    tree = QTree(problem, cache, params.alpha, params.gamma)
    rng, policy = random.Random(params.seed), POLICY_FUNCTIONS[params.policy]
    history: list[float] = []
    prev_sum, quiet, converged, e_1st, episode = 0.0, 0, False, None, 0
    while episode < params.max_episodes and not converged:
        epsilon = epsilon_schedule(episode, params.max_episodes, params.epsilon0, params.epsilon_min)
        episode += 1
        reference_episode(tree, policy, rng, epsilon, params.search == "depth", params.max_steps)
        history.append(tree.q_sum)
        quiet = quiet + 1 if abs(tree.q_sum - prev_sum) <= params.beta else 0
        prev_sum = tree.q_sum
        if optimal_weight is not None and e_1st is None:
            seq = tree.best_sequence()
            if seq is not None and problem.weight(seq) <= optimal_weight + WEIGHT_TOL:
                e_1st = episode
        converged = quiet >= params.quiet_episodes
    return dict(tree=tree, episodes=episode, converged=converged, e_1st=e_1st, history=history, cache=cache)
