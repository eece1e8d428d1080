"""Action-selection policies of the paper (Sect. 4.2) and the epsilon decay of Eq. 14.

- LRND: uniform over the offered actions.
- H-LRND: the heuristic "try the target first" (when it is offered at this node, i.e. not yet found
  unfeasible here); otherwise uniform over the others.
- H-eG: the same heuristic, then epsilon-greedy over the edge values (an edge not yet in the tree counts 0;
  ties are broken uniformly at random).

Each policy is `policy(node, offered, target, rng, epsilon) -> action`, `offered` a non-empty list of action
indices, `rng` a random.Random (seeded by the trainer: same seed, same choices).
"""
from __future__ import annotations

import random
from typing import Callable

from .q_tree import Node


def epsilon_schedule(episode: int, max_episodes: int, epsilon0: float, epsilon_min: float) -> float:
    """Eq. 14 as implemented here (exponential decay; see docs/qtree.md):
    eps_e = eps0 * (eps_min / eps0) ** (e / (E_max - 1)) for episodes e = 0 .. E_max - 1,
    so the first episode uses eps0 and the last eps_min (E_max = 1: eps0)."""
    if max_episodes <= 1:
        return epsilon0
    return epsilon0 * (epsilon_min / epsilon0) ** (episode / (max_episodes - 1))


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
