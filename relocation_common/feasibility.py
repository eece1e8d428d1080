"""The feasibility question the Q-Tree asks the motion planner (paper Eq. 11), defined once.

"Is relocating object i feasible once the objects in `removed` are gone?" The answer is a label g_U
(unfeasible), g_O (a feasible obstacle) or g_T (the feasible target), and from the real motion planner a
trajectory. Implementations: the motion planner core (stpik_motion_planner.feasibility.MotionPlanner), the
task planner node's service client, and the adapters of qtree_task_planner.oracles.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Protocol


class Label(IntEnum):
    """Eq. 11. Values match qtree_relocation_msgs/srv/PlanFeasibility."""

    UNFEASIBLE = 0  # g_U
    OBSTACLE = 1  # g_O
    TARGET = 2  # g_T


@dataclass(frozen=True)
class FeasibilityAnswer:
    label: Label
    planning_time: float = 0.0  # s
    attempts: int = 0
    message: str = ""
    trajectory: Any = None  # the motion planner's joint trajectory on success


class FeasibilityOracle(Protocol):
    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Answer for `object_id` with the objects in `removed` gone (robot starting from home)."""
        ...
