"""What a planning call gives back: the motion segments of a relocation, the work a feasibility query spent, and
PlanningError when a pick, carry or home motion cannot be planned."""
from __future__ import annotations

from dataclasses import dataclass, field

from stpik_motion_planner.planning.trajectory import Trajectory


class PlanningError(RuntimeError):
    """A pick, carry or home motion that could not be planned (the message says which stage failed)."""


@dataclass
class Segment:
    """One continuous motion of a relocation and the gripper action after it ('close', 'open' or None)."""

    name: str
    trajectory: Trajectory
    gripper_after: str | None = None


@dataclass
class QueryStats:
    """Where one query spent its work (RRT-Connect, STPIK) and STPIK's rejections."""

    rrt_time: float = 0.0
    stpik_time: float = 0.0
    rrt_calls: int = 0
    direct_paths: int = 0
    stpik_reject: list[str] = field(default_factory=list)
