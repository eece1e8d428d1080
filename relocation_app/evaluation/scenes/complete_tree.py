"""Size of a scene's complete Q-Tree: what LRND eventually builds, so the paper's LRND MP_q (Tables 1-3).

The complete tree holds every sequence of feasible relocations. A node is a sequence of removed obstacles; it has
one edge per object still on the shelf (its actions, every one a motion-planner query, Sect. 4: MP_q counts
tree edges); a feasible obstacle edge leads to a child node, a feasible target edge is a *target leaf* (a
sequence ending with the target: the paper's "feasible sequences", 10 / 20 / 20 in Sect. 5.1), an unfeasible
edge is pruned. Feasibility depends only on the removed set, so the counts are memoised per set:

  edges(S) = (N - |S|) + sum over feasible obstacles o of edges(S + {o}),   N = obstacles + target
  leaves(S) = [target feasible from S] + sum over feasible obstacles o of leaves(S + {o})

`feasible(o, S)` is any Label-valued oracle: a filled FeasibilityTable (real planner), or a scenario's
`blocking:` relation (BlockingOracle, tests).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from relocation_common.feasibility import Label

LabelOf = Callable[[str, frozenset], Label]


@dataclass(frozen=True)
class TreeSize:
    """Counts of a scene's complete Q-Tree (module docstring)."""

    edges: int          # edges of the complete Q-Tree (the paper's LRND MP_q)
    target_leaves: int  # sequences of feasible relocations ending with the target
    nodes: int          # nodes (sequences of removed obstacles, the root included)
    optimal_leaves: int  # target leaves of least total weight (Eq. 8); 0 without weights
    optimal_weight: float | None


def complete_tree(obstacles, target: str, label_of: LabelOf, weights: dict | None = None) -> TreeSize:
    """Counts of the complete tree over `obstacles` + `target` (module docstring); with `weights`, also the
    number of target leaves that reach the least total weight (one optimum: 1)."""
    obstacles = tuple(obstacles)
    n = len(obstacles) + 1
    memo: dict[frozenset, tuple[int, int, int, float, int]] = {}

    def visit(s: frozenset) -> tuple[int, int, int, float, int]:
        """(edges, leaves, nodes, best weight to a target leaf below s, leaves at that weight)."""
        if s in memo:
            return memo[s]
        edges, leaves, nodes = n - len(s), 0, 1
        best, n_best = float("inf"), 0
        if label_of(target, s) == Label.TARGET:
            leaves, best, n_best = 1, 0.0, 1
        for o in obstacles:
            if o in s or label_of(o, s) != Label.OBSTACLE:
                continue
            e, lv, nd, b, nb = visit(s | {o})
            edges, leaves, nodes = edges + e, leaves + lv, nodes + nd
            b += weights[o] if weights else 0.0
            if b < best - 1e-9:
                best, n_best = b, nb
            elif abs(b - best) <= 1e-9:
                n_best += nb
        memo[s] = (edges, leaves, nodes, best, n_best)
        return memo[s]

    e, lv, nd, b, nb = visit(frozenset())
    has = weights is not None and lv > 0
    return TreeSize(e, lv, nd, nb if has else 0, b if has else None)


def of_table(table, scenario) -> TreeSize:
    """The complete tree of `scenario` from a filled feasibility table (KeyError-free: a missing answer raises
    ValueError naming it, run the fill step)."""
    def label_of(o: str, s: frozenset) -> Label:
        lab = table.get(o, s)
        if lab is None:
            raise ValueError(f"feasibility table of {scenario.name} has no answer for {o} after {sorted(s)}; "
                             "run the fill step")
        return lab
    return complete_tree(scenario.obstacle_ids, scenario.target_id, label_of, scenario.weights)


def of_oracle(oracle, scenario) -> TreeSize:
    """The complete tree from any FeasibilityOracle (e.g. qtree_task_planner.oracles.BlockingOracle)."""
    return complete_tree(scenario.obstacle_ids, scenario.target_id,
                         lambda o, s: oracle.feasibility(o, s).label, scenario.weights)
