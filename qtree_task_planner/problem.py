"""The relocation problem the task planner solves: obstacles with weights phi_i in (0, 1] and one target.

A light, ROS-free view of a scenario (relocation_common.scenario.Scenario) or of a scene that the Q-Tree, the exact
solver and the evaluation share. Objects are indexed 0..N-1 (obstacles, in scenario order) and N (target). A scene's
problem holds every object of it, listed in the scenario or not: an unlisted object is an obstacle whose weight was
estimated (`estimated`: how), relocated like any other when the motion planner finds it feasible.

One action model (docs/qtree.md, "One action model"): relocating obstacle i costs phi_i x the factor of its action
(`ActionCosts`, config/task_planner.yaml `action_cost`); a pick's action follows from the object's pose (standing:
side_grasp; lying flat: top_grasp: relocation_common.feasibility.pick_action), so a problem carries every obstacle's
cost up front (`costs`). The Q-Tree's rewards (Eq. 13) and the exact solvers use the costs; Eq. 8's total weight is
still reported (`weight`), the total cost beside it (`cost`). With every factor 1 the costs are the weights: the
paper's problem. `action_set` names the actions the solvers choose among: what their "no sequence" proofs cover.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from relocation_common.config import ParameterError, node_section
from relocation_common.feasibility import ACTIONS, PICK_ACTIONS, pick_action
from relocation_common.paths import config_file
from relocation_common.scenario import Scenario, ShelfObject

MAX_FACTOR = 10.0  # an action factor's bound: |R_UNFEASIBLE| of Eq. 13 over the largest weight 1, so that no
# relocation is penalised more than an unfeasible try (docs/qtree.md, "One action model")


class ProblemError(ValueError):
    """A problem that cannot be solved as stated (duplicate ids, bad weight, no target)."""


@dataclass(frozen=True)
class ActionCosts:
    """The cost factor of each action kind (relocation_common.feasibility.ACTIONS): relocating object i with action k
    costs phi_i x factor(k); defaults in config/task_planner.yaml (`action_cost`), each in (0, MAX_FACTOR]."""

    side_grasp: float
    top_grasp: float
    push: float

    def __post_init__(self) -> None:
        for kind in ACTIONS:
            v = getattr(self, kind)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or \
                    not 0.0 < v <= MAX_FACTOR:
                raise ParameterError(f"action_cost.{kind} must be a number in (0, {MAX_FACTOR:g}], got {v!r}")
            object.__setattr__(self, kind, float(v))

    @classmethod
    def from_mapping(cls, d: Any) -> "ActionCosts":
        """From {action kind: factor}, every kind of ACTIONS and no other (typos are not ignored)."""
        if not isinstance(d, Mapping):
            raise ParameterError(f"action_cost must be a mapping of {', '.join(ACTIONS)} to factors, got {d!r}")
        unknown, missing = sorted(set(map(str, d)) - set(ACTIONS)), [k for k in ACTIONS if k not in d]
        if unknown or missing:
            raise ParameterError(f"action_cost: unknown kind(s) {', '.join(unknown) or '-'}, missing "
                                 f"{', '.join(missing) or '-'}; the kinds are {', '.join(ACTIONS)}")
        return cls(**{k: d[k] for k in ACTIONS})

    @classmethod
    def from_yaml(cls, path: str | Path | None = None, node: str = "task_planner") -> "ActionCosts":
        """`action_cost` of a ROS params file's `node` section (default config/task_planner.yaml: the one place of
        the defaults)."""
        path = Path(path) if path is not None else config_file("task_planner.yaml")
        try:
            return cls.from_mapping(node_section(path, node).get("action_cost"))
        except ParameterError as e:
            raise ParameterError(f"{path}: {e}") from None

    @classmethod
    def from_parameters(cls, p: Any) -> "ActionCosts":
        """From a node's parameters: p(name) of `action_cost.<kind>` (ROS flattens a nested map to dotted names)."""
        return cls.from_mapping({k: p(f"action_cost.{k}") for k in ACTIONS})

    def factor(self, kind: str) -> float:
        """The factor of action `kind`; ValueError for a kind that is not one."""
        if kind not in ACTIONS:
            raise ValueError(f"unknown action {kind!r}; the kinds are {', '.join(ACTIONS)}")
        return float(getattr(self, kind))

    def to_dict(self) -> dict[str, float]:
        """{kind: factor}."""
        return {k: self.factor(k) for k in ACTIONS}


@dataclass(frozen=True)
class RelocationProblem:
    """Obstacles (in order: action indices 0..N-1), their weights phi_i, and the target (index N); `estimated`: the
    obstacles whose weight was estimated (not listed in the scenario) -> how (e.g. "0.45 L x 600 kg/m3 = 0.27 kg")."""

    obstacles: tuple[str, ...]
    weights: Mapping[str, float]  # phi_i of every obstacle (Eq. 8, 13)
    target: str
    estimated: Mapping[str, str] = field(default_factory=dict)  # no weight given: a scene's own, not a parameter
    costs: Mapping[str, float] = field(default_factory=dict)  # obstacle -> phi_i x its action's factor (module doc);
    # one left out costs its weight (a side grasp at factor 1, the paper's)
    action_set: tuple[str, ...] = PICK_ACTIONS  # the actions the solvers choose among (their proofs' scope)

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "weights", dict(self.weights))
        object.__setattr__(self, "estimated", dict(self.estimated))
        object.__setattr__(self, "action_set", tuple(self.action_set))
        if not set(self.costs) <= set(self.obstacles):
            raise ProblemError("costs must be of obstacles")
        if not self.action_set or not set(self.action_set) <= set(ACTIONS):
            raise ProblemError(f"action_set must name actions of {', '.join(ACTIONS)}, got {self.action_set!r}")
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
        for o, c in self.costs.items():
            if isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c) or c <= 0:
                raise ProblemError(f"cost of {o!r} must be a positive number, got {c!r}")
        object.__setattr__(self, "costs", {o: float(self.costs.get(o, self.weights[o])) for o in self.obstacles})

    @classmethod
    def from_scenario(cls, scenario: Scenario, action_cost: ActionCosts | None = None) -> "RelocationProblem":
        """From a relocation_common.scenario.Scenario (already validated by its loader); with `action_cost`, each
        obstacle's pick costed as its pose takes it (`with_actions`)."""
        problem = cls(scenario.obstacle_ids, scenario.weights, scenario.target_id)
        if action_cost is None:
            return problem
        return problem.with_actions({o.id: pick_action(o.lying) for o in scenario.objects}, action_cost)

    @classmethod
    def from_bottles(cls, bottles: Sequence[ShelfObject], action_cost: ActionCosts | None = None
                     ) -> "RelocationProblem":
        """From scene objects (relocation_common.scenario.ShelfObject: id, weight, is_target, listed, weight_note,
        lying), e.g. perceived: every one of them, listed or not; with `action_cost`, each obstacle's pick costed as
        its pose takes it (`with_actions`)."""
        obstacles = [b for b in bottles if not b.is_target]
        target = next(b.id for b in bottles if b.is_target)
        problem = cls(tuple(b.id for b in obstacles), {b.id: b.weight for b in obstacles}, target,
                      {b.id: b.weight_note or "estimated" for b in obstacles if not b.listed})
        if action_cost is None:
            return problem
        return problem.with_actions({b.id: pick_action(b.lying) for b in bottles}, action_cost)

    def with_actions(self, actions: Mapping[str, str], action_cost: ActionCosts) -> "RelocationProblem":
        """This problem with every obstacle's cost phi_i x action_cost.factor(actions[i]) (module doc); an obstacle
        `actions` leaves out is taken with the side grasp."""
        return dataclasses.replace(self, costs={o: self.weights[o] * action_cost.factor(actions.get(o, PICK_ACTIONS[0]))
                                                for o in self.obstacles})

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

    def costs_line(self) -> str:
        """One line for the log and the result: the obstacles whose cost differs from their weight (an action factor
        other than 1), weight x factor = cost ("" without any)."""
        costed = [o for o in self.obstacles if self.costs[o] != self.weights[o]]
        if not costed:
            return ""
        return "costed (weight x action factor): " + ", ".join(
            f"{o} {self.weights[o]:.2f} x {self.costs[o] / self.weights[o]:.2f} = {self.costs[o]:.2f}" for o in costed)

    def weight(self, sequence: Iterable[str]) -> float:
        """Eq. 8: total weight sum phi_i of the obstacles in a sequence (the target's weight does not count)."""
        return float(sum(self.weights[o] for o in sequence if o != self.target))

    def cost(self, sequence: Iterable[str]) -> float:
        """Eq. 8 with each obstacle's cost for its weight (module doc): what the solvers minimise; the weight when
        every factor is 1."""
        return float(sum(self.costs[o] for o in sequence if o != self.target))

    @property
    def costed(self) -> bool:
        """Whether some obstacle's cost differs from its weight (an action factor other than 1 applies): results then
        report the total cost beside Eq. 8's total weight."""
        return any(self.costs[o] != self.weights[o] for o in self.obstacles)
