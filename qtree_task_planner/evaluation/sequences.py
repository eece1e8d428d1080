"""Feasible relocation sequences of a scene, counted from a complete feasibility table (docs/evaluation.md).

Definitions (with S a set of removed obstacles, "reachable" = obtainable from {} by feasible single removals):
- a *freeing set* is a reachable S from which the target is feasible;
- it is *minimal* when no reachable proper subset of it is a freeing set (every obstacle in it is needed);
- a *feasible sequence* is an order of the obstacles of a minimal freeing set in which each one is feasible when
  its turn comes (given the ones before it), followed by the target.
The optimum is the feasible sequence of least total weight (Eq. 8); every minimum-weight sequence is one of
these (all phi_i > 0, so a superfluous obstacle only adds weight).
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

from qtree_task_planner.feasibility import Label

from .feasibility_cache import FeasibilityTable, reachable_sets

WEIGHT_TOL = 1e-9


@dataclass(frozen=True)
class SequenceReport:
    n_obstacles: int
    reachable_sets: int
    target_free_at_start: bool
    initially_feasible: tuple[str, ...]
    minimal_sets: tuple[tuple[str, ...], ...]
    sequences: tuple[tuple[str, ...], ...]  # obstacles only, the target follows each
    optimal_weight: float | None
    optimal_sequences: tuple[tuple[str, ...], ...]

    @property
    def n_sequences(self) -> int:
        return len(self.sequences)

    @property
    def optimal_sets(self) -> tuple[tuple[str, ...], ...]:
        return tuple(sorted({tuple(sorted(q)) for q in self.optimal_sequences}))

    @property
    def unique_optimum(self) -> bool:
        """One optimal set of obstacles (its feasible orders all weigh the same, Eq. 8)."""
        return len(self.optimal_sets) == 1

    def to_dict(self) -> dict:
        return {"n_obstacles": self.n_obstacles, "reachable_sets": self.reachable_sets,
                "target_free_at_start": self.target_free_at_start,
                "initially_feasible": list(self.initially_feasible),
                "minimal_sets": [list(s) for s in self.minimal_sets], "n_sequences": self.n_sequences,
                "sequences": [list(s) for s in self.sequences], "optimal_weight": self.optimal_weight,
                "optimal_sequences": [list(s) for s in self.optimal_sequences],
                "optimal_sets": [list(s) for s in self.optimal_sets]}


def _orders(table: FeasibilityTable, members: frozenset[str], prefix: tuple[str, ...] = ()):
    done = frozenset(prefix)
    if done == members:
        yield prefix
        return
    for o in sorted(members - done):
        if table.get(o, done) == Label.OBSTACLE:
            yield from _orders(table, members, prefix + (o,))


def analyse(table: FeasibilityTable, scenario) -> SequenceReport:
    """Minimal freeing sets, feasible sequences and the optimum of `scenario` from a complete table."""
    weights = scenario.weights
    target = scenario.target_id
    reach = reachable_sets(table, scenario)
    reach_set = set(reach)
    missing = [s for s in reach if table.get(target, s) is None]
    if missing:
        raise ValueError(f"table of {scenario.name} is incomplete: no answer for the target with {sorted(missing[0])} "
                         "removed; run the fill step")
    freeing = [s for s in reach if table.get(target, s) == Label.TARGET]
    freeing_set = set(freeing)
    minimal = []
    for s in freeing:  # reach is sorted by size, so subsets come first
        if not any(frozenset(sub) in freeing_set and frozenset(sub) in reach_set
                   for k in range(len(s)) for sub in combinations(sorted(s), k)):
            minimal.append(s)
    seqs = [seq for s in minimal for seq in _orders(table, s)]
    best = min((sum(weights[o] for o in q) for q in seqs), default=None)
    opt = tuple(q for q in seqs if best is not None and sum(weights[o] for o in q) <= best + WEIGHT_TOL)
    init = tuple(o for o in scenario.obstacle_ids if table.get(o, frozenset()) == Label.OBSTACLE)
    return SequenceReport(len(scenario.obstacle_ids), len(reach), frozenset() in freeing_set, init,
                          tuple(tuple(sorted(s)) for s in minimal), tuple(seqs), best, opt)
