"""The reference Q-Tree training loop (paper Sect. 4.2), by the book: a policy function below picks
an action (Eq. 14 epsilon), `step` labels it (Eq. 11), rewards it (Eq. 13) and updates it (Eq. 7); Eq. 15
after each episode, the Eq. 16 stop, E_1st. The tests' oracle for the production engine
(qtree_task_planner.learning.kernel
through training.train): same seed, same tree, bit for bit."""
from __future__ import annotations

import random
from typing import Callable

from qtree_task_planner.learning.params import TrainingParams
from qtree_task_planner.learning.policies import epsilon_schedule
from qtree_task_planner.learning.q_tree import R_TARGET, R_UNFEASIBLE, Node, QTree
from qtree_task_planner.oracles import CachedOracle
from qtree_task_planner.problem import RelocationProblem
from relocation_common.feasibility import Label

WEIGHT_TOL = 1e-9


def reward(label: Label, phi: float) -> float:
    """Eq. 13 for the label of the chosen action and the weight phi_i of its object."""
    if label == Label.OBSTACLE:
        return -phi
    if label == Label.TARGET:
        return R_TARGET
    return R_UNFEASIBLE


def update(tree: QTree, node: Node, a: int, r: float, next_node: Node | None) -> float:
    """Eq. 7 on edge (node, a); next_node None means terminal (target relocated or action unfeasible)."""
    table = node.q if a in node.q else node.q_pruned
    old = table[a]
    target = r if next_node is None else r + tree.gamma * next_node.max_q()
    new = old + tree.alpha * (target - old)
    table[a] = new
    tree.q_sum += abs(new) - abs(old)
    return new


def step(tree: QTree, node: Node, a: int) -> tuple[Label, Node | None]:
    """Take action a at node: label it, reward it (Eq. 13), update (Eq. 7). Returns the label and the next
    node (None when the episode's sequence cannot continue through this edge: target or unfeasible)."""
    label = tree.edge_label(node, a)
    if label == Label.OBSTACLE:
        nxt = tree.child(node, a)
        update(tree, node, a, -tree.phi[a], nxt)
        return label, nxt
    update(tree, node, a, reward(label, 0.0), None)
    return label, None


def lrnd(node: Node, offered: list[int], target: int, rng: random.Random, epsilon: float) -> int:
    """LRND: uniform over the offered actions."""
    return offered[int(rng.random() * len(offered))]


def h_lrnd(node: Node, offered: list[int], target: int, rng: random.Random, epsilon: float) -> int:
    """H-LRND: the target when offered, else uniform."""
    if offered[-1] == target:  # offered is ascending and the target has the highest index
        return target
    return offered[int(rng.random() * len(offered))]


def epsilon_greedy(node: Node, offered: list[int], target: int, rng: random.Random, epsilon: float) -> int:
    """H-eG: target first, then with probability epsilon uniform, else the highest edge value."""
    if offered[-1] == target:
        return target
    if rng.random() < epsilon:
        return offered[int(rng.random() * len(offered))]
    q = node.q
    best_v, best = None, []
    for a in offered:
        v = q.get(a, 0.0)
        if best_v is None or v > best_v:
            best_v, best = v, [a]
        elif v == best_v:
            best.append(a)
    return best[0] if len(best) == 1 else best[int(rng.random() * len(best))]


POLICY_FUNCTIONS: dict[str, Callable[..., int]] = {"lrnd": lrnd, "h-lrnd": h_lrnd, "h-eg": epsilon_greedy}


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
        label, nxt = step(tree, node, a)
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
