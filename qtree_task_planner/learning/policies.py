"""The paper's action-selection policies (Sect. 4.2) and the epsilon decay of Eq. 14.

- LRND: uniform over the offered actions.
- H-LRND: the heuristic "try the target first" (when it is offered at this node, i.e. not yet found
  unfeasible here); otherwise uniform over the others.
- H-eG: the same heuristic, then epsilon-greedy over the edge values (an edge not yet in the tree counts 0;
  ties are broken uniformly at random).

The policies run inside the C episode kernel (kernel.py, `POLICY_CODES`); their Python reference, the tests'
oracle, is test/qtree_reference.py. The decay below is the one both use.
"""
from __future__ import annotations


def epsilon_schedule(episode: int, max_episodes: int, epsilon0: float, epsilon_min: float) -> float:
    """Eq. 14 as implemented here (exponential decay; see docs/qtree.md):
    eps_e = eps0 * (eps_min / eps0) ** (e / (E_max - 1)) for episodes e = 0 .. E_max - 1,
    so the first episode uses eps0 and the last eps_min (E_max = 1: eps0)."""
    if max_episodes <= 1:
        return epsilon0
    return epsilon0 * (epsilon_min / epsilon0) ** (episode / (max_episodes - 1))
