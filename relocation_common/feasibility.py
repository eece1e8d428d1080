"""The feasibility question the Q-Tree asks the motion planner (paper Eq. 11), defined once.

"Is relocating object i feasible once the objects in `removed` are gone?" The answer is a label g_U
(unfeasible), g_O (a feasible obstacle) or g_T (the feasible target), and from the real motion planner a
trajectory. Implementations: the motion planner core (stpik_motion_planner.feasibility.MotionPlanner), the
task planner node's service client, and the adapters of qtree_task_planner.oracles.

Blockers (issue 14). An unfeasible answer may name, per candidate grasp lane (approach yaw), the objects the hand
or arm meets there: `BlockerSet`s, the alternatives whose removal would clear an approach. A *certain* set is a
geometric fact: the lane is clear exactly when all of its objects are removed. An *uncertain* set is a suspicion
(the lane passed the screen but STPIK or RRT-Connect failed there): it claims nothing. The claim of an answer
whose sets are all certain: from `removed` or any superset of it, relocating the object needs one of the listed
lanes cleared. Empty `blockers` = no information.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Mapping, Protocol


class Label(IntEnum):
    """Eq. 11. Values match qtree_relocation_msgs/srv/PlanFeasibility."""

    UNFEASIBLE = 0  # g_U
    OBSTACLE = 1  # g_O
    TARGET = 2  # g_T


@dataclass(frozen=True)
class BlockerSet:
    """One grasp lane's blockers: the objects (not yet removed) the hand or arm meets at the pre-grasp or along
    the approach. certain: the lane is clear exactly when all of them are removed (geometric screen);
    uncertain: a suspicion that claims nothing (a failure not attributable to one set)."""

    objects: frozenset[str]
    certain: bool = True
    lane: str = ""  # e.g. "yaw +0.35"

    def __post_init__(self) -> None:
        object.__setattr__(self, "objects", frozenset(self.objects))


def claims(blockers) -> bool:
    """True if the sets make the claim "one of these lanes must be cleared": non-empty and all certain."""
    return bool(blockers) and all(b.certain for b in blockers)


@dataclass(frozen=True)
class FeasibilityAnswer:
    label: Label
    planning_time: float = 0.0  # s
    attempts: int = 0
    message: str = ""
    trajectory: Any = None  # the motion planner's joint trajectory on success
    blockers: tuple[BlockerSet, ...] = ()  # unfeasible answers: one set per candidate grasp lane (see above)


class FeasibilityOracle(Protocol):
    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Answer for `object_id` with the objects in `removed` gone (robot starting from home)."""
        ...


class LaneOracle(Protocol):
    """An oracle that can also list every object's lane blockers at once (cheap: no motion planning)."""

    def lane_blockers(self, removed: frozenset[str]) -> Mapping[str, tuple[BlockerSet, ...]] | None:
        """object -> its lanes' blocker sets with `removed` gone, for every object still there: an empty tuple
        = no lane can ever be cleared; an object left out (or None for all) = no information."""
        ...
