"""The relocation problem the task planner solves: obstacles with weights phi_i in (0, 1] and one target.

A light, ROS-free view of a scenario (relocation_common.scenario.Scenario) or of a scene that the Q-Tree, the exact
solver and the evaluation share. Objects are indexed 0..N-1 (obstacles, in scenario order) and N (target). A scene's
problem holds every object of it, listed in the scenario or not: an unlisted object is an obstacle whose weight was
estimated (`estimated`: how), relocated like any other when the motion planner finds it feasible.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

from relocation_common.scenario import Scenario, ShelfObject


class ProblemError(ValueError):
    """A problem that cannot be solved as stated (duplicate ids, bad weight, no target)."""


@dataclass(frozen=True)
class RelocationProblem:
    """Obstacles (in order: action indices 0..N-1), their weights phi_i, and the target (index N); `estimated`: the
    obstacles whose weight was estimated (not listed in the scenario) -> how (e.g. "0.45 L x 600 kg/m3 = 0.27 kg")."""

    obstacles: tuple[str, ...]
    weights: Mapping[str, float]  # phi_i of every obstacle (Eq. 8, 13)
    target: str
    estimated: Mapping[str, str] = field(default_factory=dict)  # no weight given: a scene's own, not a parameter

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "weights", dict(self.weights))
        object.__setattr__(self, "estimated", dict(self.estimated))
        if not set(self.estimated) <= set(self.obstacles):
            raise ProblemError("estimated weights must be of obstacles")
        if not isinstance(self.target, str) or not self.target:
            raise ProblemError("no target: name the object to retrieve")
        if len(set(self.obstacles)) != len(self.obstacles):
            raise ProblemError("duplicate obstacle ids")
        if self.target in self.obstacles:
            raise ProblemError(f"target {self.target!r} is also listed as an obstacle")
        if set(self.weights) != set(self.obstacles):
            raise ProblemError("weights must give phi_i for exactly the obstacles")
        for o, w in self.weights.items():
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not math.isfinite(w) or not 0 < w <= 1:
                raise ProblemError(f"weight of {o!r} must be in (0, 1], got {w!r}")

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> "RelocationProblem":
        """From a relocation_common.scenario.Scenario (already validated by its loader)."""
        return cls(scenario.obstacle_ids, scenario.weights, scenario.target_id)

    @classmethod
    def from_bottles(cls, bottles: Sequence[ShelfObject]) -> "RelocationProblem":
        """From scene objects (relocation_common.scenario.ShelfObject: id, weight, is_target, listed, weight_note),
        e.g. perceived: every one of them, listed or not."""
        obstacles = [b for b in bottles if not b.is_target]
        target = next(b.id for b in bottles if b.is_target)
        return cls(tuple(b.id for b in obstacles), {b.id: b.weight for b in obstacles}, target,
                   {b.id: b.weight_note or "estimated" for b in obstacles if not b.listed})

    @property
    def ids(self) -> tuple[str, ...]:
        """Obstacles then the target: index -> id."""
        return self.obstacles + (self.target,)

    @property
    def n(self) -> int:
        """N, the number of obstacles."""
        return len(self.obstacles)

    def unlisted_line(self) -> str:
        """One line for the log and the result: the obstacles the scenario does not list with their estimated
        weights ("" without any)."""
        if not self.estimated:
            return ""
        return "unlisted (obstacles, weight estimated): " + ", ".join(
            f"{o} phi {self.weights[o]:.2f} ({note})" for o, note in sorted(self.estimated.items()))

    def weight(self, sequence: Iterable[str]) -> float:
        """Eq. 8: total weight sum phi_i of the obstacles in a sequence (the target's weight does not count)."""
        return float(sum(self.weights[o] for o in sequence if o != self.target))
