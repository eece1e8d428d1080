"""The feasibility question the Q-Tree asks the motion planner (paper Eq. 11), defined once.

"Is relocating object i feasible once the objects in `removed` are gone?" The answer is a label g_U
(unfeasible), g_O (a feasible obstacle) or g_T (the feasible target), and from the real motion planner a
trajectory. Implementations: the motion planner core (stpik_motion_planner.planning.planner.MotionPlanner), the
task planner node's service client, and the adapters of qtree_task_planner.oracles.

Blockers (docs/motion_planner.md, "Blockers"). An unfeasible answer may name, per candidate grasp lane (approach yaw),
the objects the hand or arm meets there: `BlockerSet`s, the alternatives whose removal would clear an approach. A
*certain* set is a geometric fact: the lane is clear exactly when all of its objects are removed. An *uncertain* set is
a suspicion (the lane passed the screen but STPIK or RRT-Connect failed there): it claims nothing. The claim of an
answer whose sets are all certain: from `removed` or any superset of it, relocating the object needs one of the listed
lanes cleared. Empty `blockers` = no information.

An object the hand cannot grasp (a box, a lying bottle, one wider than the open hand...) is answered g_U with a
message starting NO_GRASP and the reason: it stays an obstacle, never relocated, whatever is removed.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Callable, Mapping, Protocol, Sequence

NO_GRASP = "no grasp: "  # the start of the g_U message of an object the hand cannot grasp (module docstring)
OUTCOME_UNKNOWN = "outcome unknown"  # the end of a RelocateObject result whose outcome no scene showed (the motion
# planner's goal_check.outcome: not a success; the task planner's closed loop looks at its own scene)


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


def claims(blockers: Sequence[BlockerSet]) -> bool:
    """True if the sets make the claim "one of these lanes must be cleared": non-empty and all certain."""
    return bool(blockers) and all(b.certain for b in blockers)


@dataclass(frozen=True)
class FeasibilityAnswer:
    """The motion planner's answer to one feasibility question: the label of Eq. 11 and how it was reached."""

    label: Label
    planning_time: float = 0.0  # s
    attempts: int = 0
    message: str = ""
    trajectory: Any = None  # the motion planner's joint trajectory on success
    blockers: tuple[BlockerSet, ...] = ()  # unfeasible answers: one set per candidate grasp lane (see above)


class FeasibilityOracle(Protocol):
    """Anything that answers the feasibility question of Eq. 11 for one object and a removed set."""

    def feasibility(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """Answer for `object_id` with the objects in `removed` gone (robot starting from home)."""
        ...


class LaneOracle(Protocol):
    """An oracle that can also list every object's lane blockers at once (cheap: no motion planning)."""

    def lane_blockers(self, removed: frozenset[str]) -> Mapping[str, tuple[BlockerSet, ...]] | None:
        """object -> its lanes' blocker sets with `removed` gone, for every object still there: an empty tuple
        = no lane can ever be cleared; an object left out (or None for all) = no information."""
        ...


Query = tuple[str, frozenset]  # (object_id, removed)
OnAnswer = Callable[[Query, FeasibilityAnswer], Any]  # called with each query's answer as it arrives


class BatchOracle(Protocol):
    """An oracle that can keep several questions in flight (planner replicas: docs/architecture.md). `in_flight`
    is how many it answers at once right now (1: no gain in batching); `feasibility_many` answers every query, calling
    `on_answer(query, answer)` as each arrives (so a caller keeps what came back before an error), and returns
    the answers in the queries' order."""

    in_flight: int

    def feasibility_many(self, queries: list[Query], on_answer: OnAnswer | None = None) -> list[FeasibilityAnswer]:
        """Answer every query, in the queries' order (see the class docstring for `on_answer`)."""
        ...


def in_flight(oracle: FeasibilityOracle | BatchOracle) -> int:
    """How many questions `oracle` answers at once (1 for a plain FeasibilityOracle)."""
    return max(1, int(getattr(oracle, "in_flight", 1)))


def ask_many(oracle: Any, queries: list[Query], on_answer: OnAnswer | None = None) -> list[FeasibilityAnswer]:
    """Every query's answer, in parallel when the oracle is a BatchOracle, else one after the other."""
    many = getattr(oracle, "feasibility_many", None)
    if many is not None and len(queries) > 1:
        return many(queries, on_answer)
    out = []
    for q in queries:
        out.append(oracle.feasibility(*q))
        if on_answer is not None:
            on_answer(q, out[-1])
    return out


def destination_slot(n_removed: int, free: Sequence[int]) -> int:
    """The bottom-shelf slot a relocation sent with `n_removed` objects removed goes to, from the `free` slot
    indices of the scene: slot n_removed, the one a certified feasible answer planned the carry to (the removed
    objects in the other slots: docs/motion_planner.md, "The certified slot"), when it is free; else the first free
    one (its carry planned at execution, not certified). ValueError when no slot is free."""
    if not free:
        raise ValueError("no free slot on the bottom shelf")
    return n_removed if n_removed in free else min(free)


def replica_namespace(k: int) -> str:
    """The ROS namespace of motion planner replica k >= 1 (replica 0 is the motion planner itself)."""
    return f"/replica_{k}"


def replica_services(service: str, replicas: int) -> list[str]:
    """The PlanFeasibility services of `replicas` planners: `service`, then the same name under each replica's
    namespace (a replica is the motion_planner node started with `-r __ns:=/replica_<k>`)."""
    return [service] + [replica_namespace(k) + "/" + service.lstrip("/") for k in range(1, replicas)]
