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

from relocation_app.evaluation.feasibility_cache import FeasibilityTable, reachable_sets
from relocation_common.feasibility import Label

WEIGHT_TOL = 1e-9


@dataclass(frozen=True)
class SequenceReport:
    """The feasible sequences of a scene and their optimum (module docstring)."""

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
        """Number of feasible sequences."""
        return len(self.sequences)

    @property
    def optimal_sets(self) -> tuple[tuple[str, ...], ...]:
        """The obstacle sets of the optimal sequences, each sorted."""
        return tuple(sorted({tuple(sorted(q)) for q in self.optimal_sequences}))

    @property
    def unique_optimum(self) -> bool:
        """One optimal set of obstacles (its feasible orders all weigh the same, Eq. 8)."""
        return len(self.optimal_sets) == 1

    def to_dict(self) -> dict:
        """The report as plain JSON."""
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


def discounted_optimum(table: FeasibilityTable, scenario, gamma: float) -> tuple[tuple[str, ...], float] | None:
    """The sequence a Q-Tree converges to with discount `gamma` (the greedy path of the fixed point of Eq. 7 with
    the rewards of Eq. 13), and its Eq. 8 weight; None if the target cannot be freed.

    The fixed point depends only on the removed set S: V(S) = max(100 if the target is feasible from S,
    max over feasible obstacles o of -phi_o + gamma V(S + {o})), 0 when nothing is feasible (unfeasible edges are
    pruned and leave the max, Eq. 7 as implemented). Ties go to the lowest action index, as in
    QTree.best_path. With gamma = 1 this is the Eq. 8 optimum (100 - total weight); with gamma < 1 the +100 and
    the weights are discounted per step, so fewer objects, and heavy objects late, are preferred."""
    weights, target = scenario.weights, scenario.target_id
    actions = list(scenario.obstacle_ids) + [target]
    memo: dict[frozenset[str], float] = {}

    def options(s: frozenset[str]) -> list[tuple[float, int, str]]:
        out = []
        for k, o in enumerate(actions):
            if o in s:
                continue
            lab = table.get(o, s)
            if o == target and lab == Label.TARGET:
                out.append((100.0, k, o))
            elif o != target and lab == Label.OBSTACLE:
                out.append((-weights[o] + gamma * value(s | {o}), k, o))
        return out

    def value(s: frozenset[str]) -> float:
        if s not in memo:
            memo[s] = max((v for v, _, _ in options(s)), default=0.0)
        return memo[s]

    s: frozenset[str] = frozenset()
    seq: list[str] = []
    for _ in actions:
        opts = options(s)
        if not opts:
            return None
        best = max(v for v, _, _ in opts)
        _, _, o = min((k, k, o) for v, k, o in opts if v >= best - 1e-12)
        if o == target:
            return tuple(seq), sum(weights[x] for x in seq)
        seq.append(o)
        s = s | {o}
    return None
