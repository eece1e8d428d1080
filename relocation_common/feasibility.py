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

Actions (docs/qtree.md, "One action model"). A feasible answer names its action: `SIDE_GRASP` (a standing cylinder or
box, taken from the side as in the paper), `TOP_GRASP` (a cylinder lying flat, taken from above) or `PUSH` (a
non-prehensile push, asked for by name); the pick an object's pose takes is `pick_action`, so the task planner knows
each pick's kind, and its cost, before it asks.

An object the hand cannot grasp (a lying bottle, one wider than the open hand, a box too wide...) is answered g_U with a
message starting NO_GRASP and the reason: it stays an obstacle, never relocated, whatever is removed.

Certification (docs/motion_planner.md, "Lazy certification"). A feasible answer is the pick (home -> pre-grasp ->
grasp), as in the paper. Whether the whole relocation plans from it (carry to slot len(removed), release, retreat,
way home) is its own question, `CertifyingOracle.certify`, asked only for the answers on a sequence about to be
committed to (the A*'s optimum, the learned sequence). A pick alone names its near set (below: `is_pick`); a feasible
answer without one is final (certified already, as an eager planner's, or from an oracle that does not certify), and
so is every answer of an oracle without `certify`.

Reuse (`reuses`, `claim_holds`). A feasible answer may carry `near`: every object whose place on the top shelf some
part of the arm, the hand or the Cartesian planner's hand proxy came within the planner's `reuse_distance` of, along
the answer's motion (removed or not). Objects farther away entered no check of that motion, so the same motion
answers (o, R') feasible when every object near it that was absent then is absent now: R' >= R & near. An unfeasible
answer whose blocker sets all claim (certain) answers (o, R') for R' >= R unfeasible while no lane is cleared.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Callable, Iterable, Mapping, Protocol, Sequence

NO_GRASP = "no grasp: "  # the start of the g_U message of an object the hand cannot grasp (module docstring)
OUTCOME_UNKNOWN = "outcome unknown"  # the end of a RelocateObject result whose outcome no scene showed (the motion
# planner's goal_check.outcome: not a success; the task planner's closed loop looks at its own scene)


SIDE_GRASP = "side_grasp"  # PlanFeasibility's `action` of a feasible pick of a standing object
TOP_GRASP = "top_grasp"  # ... of a cylinder lying flat (from above, or along its axis under a low board)
PUSH = "push"  # ... of a push (PlanFeasibility request action "push")
PICK_ACTIONS = (SIDE_GRASP, TOP_GRASP)  # the pick actions: an object's pose takes one of them (`pick_action`)
ACTIONS = PICK_ACTIONS + (PUSH,)  # every action kind of the action model


def pick_action(lying: bool) -> str:
    """The pick an object's pose takes (module docstring, "Actions"): TOP_GRASP for a cylinder lying flat, SIDE_GRASP
    for a standing object (a leaning one is no grasp at all: the planner says so)."""
    return TOP_GRASP if lying else SIDE_GRASP


def action_set(actions: Sequence[str]) -> str:
    """How a proof names the actions it covers: 'the actions side_grasp, top_grasp'."""
    return "the action" + ("s " if len(actions) != 1 else " ") + ", ".join(actions)


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
    near: frozenset[str] | None = None  # a feasible pick alone: the objects near its motion (module doc); None: final
    action: str = ""  # a feasible answer's action (SIDE_GRASP, TOP_GRASP, PUSH; module doc, "Actions"); "" unknown


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


class CertifyingOracle(Protocol):
    """An oracle that certifies a feasible answer for its whole relocation (the module docstring)."""

    def certify(self, object_id: str, removed: frozenset[str]) -> FeasibilityAnswer:
        """OBSTACLE / TARGET with the certified pick when the whole relocation of `object_id` after `removed` plans
        (pick, carry to slot len(removed) with the removed objects in the other slots, release, retreat, home);
        UNFEASIBLE with the reason otherwise."""
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


def certifies(oracle: Any) -> bool:
    """Whether `oracle` certifies (CertifyingOracle); one that does not gives final answers (module docstring)."""
    return callable(getattr(oracle, "certify", None))


def certify_many(oracle: Any, queries: list[Query], on_answer: OnAnswer | None = None) -> list[FeasibilityAnswer]:
    """Every query's certification, in parallel when the oracle has `certify_many` (planner replicas), else one
    after the other; an oracle that does not certify gives final answers: its feasibility answers are returned."""
    many = getattr(oracle, "certify_many", None)
    if many is not None and len(queries) > 1:
        return many(queries, on_answer)
    ask = oracle.certify if certifies(oracle) else oracle.feasibility
    out = []
    for q in queries:
        out.append(ask(*q))
        if on_answer is not None:
            on_answer(q, out[-1])
    return out


def is_pick(answer: FeasibilityAnswer) -> bool:
    """Whether `answer` is a feasible pick alone, to be certified before it is committed to (it names its near set);
    any other answer is final (module docstring)."""
    return answer.near is not None and Label(answer.label) != Label.UNFEASIBLE


def reuses(answer: FeasibilityAnswer, removed: frozenset[str], asked: Iterable[str]) -> bool:
    """Whether the feasible `answer` given for (o, removed) answers (o, asked) with the same motion: its near set
    is known and every object near the motion that was absent then is absent now (asked >= removed & near)."""
    return answer.near is not None and Label(answer.label) != Label.UNFEASIBLE and \
        (removed & answer.near) <= frozenset(asked)


def claim_holds(answer: FeasibilityAnswer, removed: frozenset[str], asked: frozenset[str]) -> bool:
    """Whether the unfeasible `answer` given for (o, removed) answers (o, asked) unfeasible: its blocker sets all
    claim (certain), asked >= removed, and no lane is cleared in `asked`."""
    return Label(answer.label) == Label.UNFEASIBLE and claims(answer.blockers) and removed <= asked and \
        not any(b.objects <= asked for b in answer.blockers)


def default_replicas() -> int:
    """Motion planner replicas when none is asked for: one per core of this machine (docs/reliability.md, "Planner
    replicas"), at most MAX_DEFAULT_REPLICAS."""
    return max(1, min(MAX_DEFAULT_REPLICAS, os.cpu_count() or 1))


MAX_DEFAULT_REPLICAS = 8


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
