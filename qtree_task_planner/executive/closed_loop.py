"""Closed-loop retrieval, ROS-free: check the world after every relocation, re-plan when it differs, recover.

The paper executes the learned sequence open-loop (Sect. 5). Here, after each relocation a scene perceived after
it ended is checked against the plan (`verify_relocation`: the moved bottle on the bottom shelf at its slot, every
other bottle where it was, the target present). When the world differs, when a new object is seen (one present now
and absent before: a hidden object revealed behind the relocated one, or an object the scenario does not list seen
for the first time; `new_objects`), or a relocation failed (the motion planner's recovery has brought the arm home
and the bottle back), the remaining retrieval problem is built from
the perceived scene (`remaining_problem`: relocated bottles out, moved ones at their new poses, newly seen ones in)
and solved again (an injected re-planner: `qtree_task_planner.executive.replan` over the exact blocker A*, Eq. 8),
with the
failed option marked so that it is not proposed again. The executor gives up only when no sequence remains, with
the reason in one line. The free slots of the bottom shelf bound every sequence (`check_capacity`): a sequence
relocating more objects than there are free slots is never executed.

A relocation whose outcome the motion planner could not see (no scene after its motion: its message ends with
"outcome unknown", relocation_common.feasibility.OUTCOME_UNKNOWN; perception restarting, say) is neither a success
nor a failure of the option: the scene perceived after it is checked as after any relocation, and the check
decides. A relocation the motion planner's restart interrupted is a failure of time (TRANSIENT): re-planned, and
its option tried again.

Nothing here talks to ROS: the node supplies `relocate(object_id, removed) -> (ok, message)` (the RelocateObject
action), `perceive() -> scene` (a scene perceived after the call) and `replan(problem, banned)`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

from qtree_task_planner.executive.push import Pusher, PushRecord
from qtree_task_planner.problem import ActionCosts, ProblemError, RelocationProblem
from relocation_common.config import ParameterError, node_section
from relocation_common.feasibility import OUTCOME_UNKNOWN, destination_slot, pick_action
from relocation_common.paths import config_file
from relocation_common.scenario import PALETTE, TARGET_RGB, Scenario, ShelfObject
from relocation_common.shelf_object import UPRIGHT_TILT, Footprint, support_height


# ------------------------------------------------------------------------------------------------ the scene
@dataclass(frozen=True)
class SeenObject:
    """An object as perceived: centre of its base (base frame, m), tilt of its axis from the vertical (rad; 0 for a
    perception that only sees upright bottles), and what ObjectState carries besides (weight phi, target, size,
    shape; `listed` false: the scenario does not list it, `weight_note` says how its weight was estimated; a box's
    `size` and the `yaw` of a box or of a lying cylinder's axis, as ShelfObject has them: its `footprint`)."""

    id: str
    x: float
    y: float
    z: float
    weight: float = 1.0
    is_target: bool = False
    tilt: float = 0.0
    radius: float = 0.033
    height: float = 0.16
    label: str = ""
    shape: str = "cylinder"
    listed: bool = True
    weight_note: str = ""
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0

    def footprint(self) -> Footprint:
        """Its outline on its board (ShelfObject.footprint): a standing cylinder's base circle, a box's rectangle, a
        lying cylinder's rectangle centred half its length along its axis from its base centre (x, y)."""
        lying = self.shape == "cylinder" and self.tilt > UPRIGHT_TILT
        along = self.height / 2 * math.sin(self.tilt) if lying else 0.0
        o = ShelfObject(self.id, self.label, TARGET_RGB, self.weight, self.x + along * math.cos(self.yaw),
                        self.y + along * math.sin(self.yaw), self.radius, self.height, shape=self.shape, size=self.size,
                        yaw=self.yaw, lying=lying, tilt=self.tilt if lying else None)
        return o.footprint()


Scene = Mapping[str, SeenObject]


def scene_of(objects: Iterable[SeenObject]) -> dict[str, SeenObject]:
    """id -> object."""
    return {o.id: o for o in objects}


def seen_object(o: ShelfObject) -> SeenObject:
    """An object as perceived (ros_conversions.msg_to_objects) as the closed loop's SeenObject: its base centre
    (a lying cylinder's lower end face), the tilt of its axis."""
    x, y, z = (float(v) for v in o.base())
    return SeenObject(o.id, x, y, z, o.weight, o.is_target, o.axis_tilt, o.radius, o.height, o.label, o.shape,
                      o.listed, o.weight_note, o.size, o.yaw)


def scene_from_scenario(scenario: Scenario) -> dict[str, SeenObject]:
    """The scenario's bottles where it puts them: upright on the top shelf (the world the first plan assumes)."""
    z = scenario.shelf.top_z
    return scene_of(SeenObject(b.id, b.x, b.y, z, b.weight, b.is_target, 0.0, b.radius, b.height, b.label, b.shape,
                               b.listed, b.weight_note, b.size, b.yaw) for b in scenario.objects)


@dataclass(frozen=True)
class Tolerances:
    """How far the perceived world may be from the planned one and still be "as planned": config/task_planner.yaml
    `world_tolerance` (slot, still, board; the one place of their values); tilt is "standing" as the whole project
    reads it (relocation_common.shelf_object.UPRIGHT_TILT), not a parameter."""

    slot: float  # m in xy: the relocated bottle from its slot
    still: float  # m in xy: every other bottle from where it was
    board: float  # m in z: a bottle's support from a board's surface
    tilt: float = UPRIGHT_TILT  # rad: standing upright

    KEYS = ("slot", "still", "board")

    def __post_init__(self) -> None:
        for name in (*self.KEYS, "tilt"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ParameterError(f"world_tolerance.{name} must be a positive number (m), got {v!r}")

    @classmethod
    def from_parameters(cls, p: Callable[[str], Any]) -> "Tolerances":
        """From a node's parameters: p(name) of `world_tolerance.<key>` (ROS flattens a nested map)."""
        return cls(**{k: p(f"world_tolerance.{k}") for k in cls.KEYS})

    @classmethod
    def from_yaml(cls, path: str | Path | None = None, node: str = "task_planner") -> "Tolerances":
        """`world_tolerance` of a ROS params file's `node` section (default config/task_planner.yaml)."""
        path = Path(path) if path is not None else config_file("task_planner.yaml")
        d = node_section(path, node).get("world_tolerance")
        if not isinstance(d, Mapping) or set(d) != set(cls.KEYS):
            raise ParameterError(f"{path}: world_tolerance must map exactly {', '.join(cls.KEYS)} to metres, "
                                 f"got {d!r}")
        return cls(**{k: d[k] for k in cls.KEYS})


@lru_cache(maxsize=1)
def configured() -> Tolerances:
    """The tolerances of config/task_planner.yaml: what a caller that passes none gets (read once)."""
    return Tolerances.from_yaml()


def _support(o: SeenObject) -> float:
    """Height of the surface the object rests on (relocation_common.shelf_object.support_height)."""
    return support_height(o.z, o.radius, o.tilt)


def board_of(o: SeenObject, scenario: Scenario, tol: Tolerances) -> str | None:
    """'top' or 'bottom' when the object rests on that board of the shelf, standing or lying, else None: its
    support within tol.board of the board, its footprint's centre over it (Shelf.board_of, the motion planner's
    rule)."""
    return scenario.shelf.board_of(o.footprint().centre, _support(o), tol.board)


def _at(o: SeenObject) -> str:
    return f"({o.x:.3f}, {o.y:.3f}, {o.z:.3f})"


# ------------------------------------------------------------------------------------------------ verification
@dataclass(frozen=True)
class Difference:
    """One way the perceived world differs from the plan: kind (not_at_slot, not_seen, moved, tipped,
    target_missing; or new: a new object, `new_objects`), the object, and one line for the user."""

    kind: str
    object_id: str
    line: str


@dataclass(frozen=True)
class Verification:
    """The check after one relocation: what differs from the plan (nothing: ok), and the new objects seen (no
    fault of the relocation: the rest is re-planned with them)."""

    object_id: str
    differences: tuple[Difference, ...] = ()
    unseen_place: bool = False  # the bottle left the top shelf, its place was not seen (bottom shelf out of view)
    new: tuple[Difference, ...] = ()

    @property
    def ok(self) -> bool:
        """True when the world is as planned (as far as it was seen: `unseen_place`)."""
        return not self.differences

    def summary(self) -> str:
        """One line: 'as planned' or the first difference (and how many more); then the new objects."""
        new = "".join(f"; {d.line}" for d in self.new)
        if self.ok and self.unseen_place:
            return (f"{self.object_id} left the top shelf as planned; its place on the bottom shelf was not seen "
                    "(unverified)") + new
        if self.ok:
            return f"{self.object_id} relocated as planned" + new
        more = len(self.differences) - 1
        return self.differences[0].line + (f" (and {more} more difference{'s' * (more > 1)})" if more else "") + new

    def to_dict(self) -> dict[str, Any]:
        """For the feedback and the result (and report.json)."""
        return {"object": self.object_id, "ok": self.ok, "differences": [d.line for d in self.differences],
                "place_seen": not self.unseen_place, "new": [d.line for d in self.new]}


def verify_relocation(planned_object: str, slot_pose: tuple[float, float, float], before_scene: Scene,
                      after_scene: Scene, tolerances: Tolerances | None = None, bottom_seen: bool = True
                      ) -> Verification:
    """Check a scene perceived after relocating `planned_object` against the plan: that object upright on the bottom
    shelf at `slot_pose` (x, y, z of the board's surface) within tolerances.slot (one that tipped over there is
    relocated, `board_of`, but not as planned: a difference that says so); every other object of
    `before_scene` where it was (tolerances.still in xy, board in z, still standing); the target present. Returns
    every difference found, one line each, and the new objects (`new_objects`: not a difference, a re-plan).
    `bottom_seen` False (a camera that does not see the bottom shelf): a bottle not seen there is no difference
    (the relocated one must only have left the top shelf)."""
    tol, diffs = tolerances or configured(), []
    moved = after_scene.get(planned_object)
    sx, sy, sz = slot_pose
    if moved is None:
        if bottom_seen:
            diffs.append(Difference("not_seen", planned_object, f"{planned_object} is not seen after its relocation"))
    else:
        off = math.hypot(moved.x - sx, moved.y - sy)
        if abs(_support(moved) - sz) <= tol.board and moved.tilt > tol.tilt:  # relocated, but lying: not as planned
            at = moved.footprint().centre
            diffs.append(Difference("not_at_slot", planned_object, f"{planned_object} tipped over on the bottom shelf "
                                    f"({math.degrees(moved.tilt):.0f} deg), lying {100 * math.dist(at, (sx, sy)):.1f} "
                                    f"cm from its slot ({sx:.3f}, {sy:.3f})"))
        elif abs(_support(moved) - sz) > tol.board or moved.tilt > tol.tilt:
            lying = f", tipped {math.degrees(moved.tilt):.0f} deg" if moved.tilt > tol.tilt else ""
            diffs.append(Difference("not_at_slot", planned_object,
                                    f"{planned_object} is not on the bottom shelf: at {_at(moved)}{lying}"))
        elif off > tol.slot:
            diffs.append(Difference("not_at_slot", planned_object, f"{planned_object} is on the bottom shelf "
                                    f"{100 * off:.1f} cm from its slot ({sx:.3f}, {sy:.3f})"))
    for oid, was in sorted(before_scene.items()):
        if oid == planned_object:
            continue
        now = after_scene.get(oid)
        if now is None and not bottom_seen and abs(_support(was) - sz) <= tol.board:
            continue  # on the bottom shelf, out of view
        if now is None:
            kind = "target_missing" if was.is_target else "not_seen"
            diffs.append(Difference(kind, oid, f"{'target ' if was.is_target else ''}{oid} is no longer seen "
                                    f"(was at {_at(was)})"))
            continue
        d = math.hypot(now.x - was.x, now.y - was.y)
        if now.tilt > tol.tilt >= was.tilt:
            diffs.append(Difference("tipped", oid, f"{oid} tipped over ({math.degrees(now.tilt):.0f} deg) at "
                                    f"{_at(now)}"))
        elif d > tol.still or abs(_support(now) - _support(was)) > tol.board:
            diffs.append(Difference("moved", oid, f"{oid} moved by {100 * d:.1f} cm: {_at(was)} -> {_at(now)}"))
    return Verification(planned_object, tuple(diffs), unseen_place=moved is None and not bottom_seen,
                        new=new_objects(before_scene, after_scene, planned_object))


def new_objects(before_scene: Scene, after_scene: Scene, planned_object: str) -> tuple[Difference, ...]:
    """The objects of `after_scene` absent from `before_scene` (a hidden one revealed, an unlisted one seen for
    the first time), one line each: 'new object u3 (box, 0.31 kg est.) at (0.84, 0.12)'."""
    out = []
    for oid in sorted(set(after_scene) - set(before_scene) - {planned_object}):
        o = after_scene[oid]
        what = f"{o.weight:.2f} kg est." if not o.listed else f"listed, phi {o.weight:.2f}"
        out.append(Difference("new", oid, f"new object {oid} ({o.shape}, {what}) at ({o.x:.2f}, {o.y:.2f})"))
    return tuple(out)


# ------------------------------------------------------------------------------------------------ remaining problem
@dataclass(frozen=True)
class RemainingProblem:
    """What is left to solve, from a perceived scene. `problem` (None when there is none: `reason` says why) has
    the obstacles still on the top shelf and the target; `bottles` are those at their perceived poses (the
    planner's scene); `gone` every known object off the top shelf (relocated, dropped, fallen, unseen): the
    feasibility questions of a set S of `problem` are asked with gone | S removed."""

    problem: RelocationProblem | None
    bottles: tuple[ShelfObject, ...]
    relocated: tuple[str, ...]  # verified relocations, in order
    gone: frozenset[str]
    moved: Mapping[str, tuple[float, float]]  # on the top shelf, away from the scenario's pose
    new: tuple[str, ...]  # seen, not in the scenario (as the executor was given it)
    unseen: tuple[str, ...]  # in the scenario, not seen
    tipped: tuple[str, ...]  # on the top shelf, lying
    free_slots: tuple[int, ...]  # indices of the scenario's slots with no bottle on or near them
    reason: str = ""
    target_retrieved: bool = False

    def geometry(self) -> dict[str, tuple[float, float, float]]:
        """id -> (x, y, tilt) of every object on the top shelf: what feasibility answers depend on."""
        tilts = set(self.tipped)
        return {b.id: (b.x, b.y, math.pi / 2 if b.id in tilts else 0.0) for b in self.bottles}

    def to_dict(self) -> dict[str, Any]:
        """For the feedback, the result and report.json."""
        return {"obstacles": list(self.problem.obstacles) if self.problem else [], "relocated": list(self.relocated),
                "gone": sorted(self.gone), "moved": {k: list(v) for k, v in self.moved.items()},
                "new": list(self.new), "unseen": list(self.unseen), "tipped": list(self.tipped),
                "free_slots": list(self.free_slots), "reason": self.reason}


def free_slots(scenario: Scenario, scene: Scene, tol: Tolerances | None = None) -> tuple[int, ...]:
    """Indices of the scenario's slots that no object on the bottom shelf occupies: one is taken when the widest
    object of the scenario, standing on the slot at any turn, would overlap an object's footprint there (a standing
    bottle's circle; a box or a lying bottle by its rectangle, as the scene gives its size). The rule is
    Scenario.free_slots: the motion planner's destination reads the same."""
    tol = tol or configured()
    return scenario.free_slots(o.footprint() for o in scene.values() if board_of(o, scenario, tol) == "bottom")


def remaining_problem(scenario: Scenario, perceived_scene: Scene, relocated: Iterable[str],
                      tolerances: Tolerances | None = None, action_cost: ActionCosts | None = None
                      ) -> RemainingProblem:
    """The retrieval problem left in `perceived_scene`: objects resting on the top shelf (at their perceived poses,
    newly seen ones included with their perceived weight) are in; relocated ones and anything else off the top
    shelf or unseen are out. With `action_cost`, each obstacle costs its weight times the factor of the pick its pose
    takes (a tipped one: top_grasp; problem.RelocationProblem.with_actions). No problem (reason given) when the target
    is unseen, off the shelf, or already on the bottom shelf (`target_retrieved`; also when it is in `relocated` and
    not seen: the bottom shelf out of view)."""
    relocated, tol = tuple(relocated), tolerances or configured()
    known = set(scenario.ids)
    top = {oid: o for oid, o in perceived_scene.items() if board_of(o, scenario, tol) == "top"}
    moved = {oid: (o.x, o.y) for oid, o in top.items() if oid in known and
             math.hypot(o.x - scenario.object(oid).x, o.y - scenario.object(oid).y) > tol.still}
    base = RemainingProblem(None, (), relocated, frozenset((known | set(perceived_scene)) - set(top)), moved,
                            new=tuple(sorted(set(perceived_scene) - known)),
                            unseen=tuple(sorted(known - set(perceived_scene))),
                            tipped=tuple(sorted(oid for oid, o in top.items() if o.tilt > tol.tilt)),
                            free_slots=free_slots(scenario, perceived_scene, tol))
    targets = [o for o in perceived_scene.values() if o.is_target]
    if not targets and scenario.target_id in relocated:  # relocated, and out of view on the bottom shelf
        return replace(base, reason=f"target {scenario.target_id} relocated (not seen: the bottom shelf is out of "
                       "view)", target_retrieved=True)
    if len(targets) != 1:
        return replace(base, reason=f"target {scenario.target_id} is not seen" if not targets else
                       f"{len(targets)} targets seen: {', '.join(sorted(o.id for o in targets))}")
    t = targets[0]
    where = board_of(t, scenario, tol)
    if where != "top":
        why = (f"target {t.id} is already on the bottom shelf" if where == "bottom" else
               f"target {t.id} is off the shelf at {_at(t)}: it cannot be retrieved from there")
        return replace(base, reason=why, target_retrieved=where == "bottom")
    bottles = tuple(_bottle(o, scenario) for _, o in sorted(top.items()))
    try:
        problem = RelocationProblem.from_bottles(bottles)
    except ProblemError as e:
        return replace(base, bottles=bottles, reason=f"the perceived scene is not a problem: {e}")
    if action_cost is not None:
        problem = problem.with_actions({b.id: pick_action(b.id in base.tipped) for b in bottles}, action_cost)
    return replace(base, problem=problem, bottles=bottles)


def _bottle(o: SeenObject, scenario: Scenario) -> ShelfObject:
    """A perceived object as a scenario ShelfObject (colour from the scenario when known)."""
    known = o.id in scenario.ids
    label = scenario.object(o.id).label if known else (o.label or "gray")
    rgb = scenario.object(o.id).rgb if known else TARGET_RGB if o.is_target else PALETTE.get(label, (0.5, 0.5, 0.5))
    weight = 1.0 if o.is_target else min(1.0, max(1e-3, o.weight))
    return ShelfObject(o.id, label, rgb, weight, o.x, o.y, o.radius, o.height, o.is_target, listed=o.listed,
                       weight_note=o.weight_note, support_z=_support(o))


def check_capacity(sequence: Iterable[str], free: int) -> str | None:
    """Why `sequence` cannot be executed with `free` free slots (every relocated object, the target included, takes
    one), or None when it fits."""
    n = len(tuple(sequence))
    if n > free:
        return f"the sequence relocates {n} objects but only {free} slot{'s' * (free != 1)} of the bottom shelf " \
               f"{'are' if free != 1 else 'is'} free"
    return None


# ------------------------------------------------------------------------------------------------ the executor
@dataclass(frozen=True)
class Option:
    """A failed option, not to be proposed again: relocating `object_id` with exactly `removed` gone (None: with
    any set, after the object failed `max_attempts` times)."""

    object_id: str
    removed: frozenset[str] | None = None

    def bans(self, object_id: str, removed: frozenset[str]) -> bool:
        """True when this option forbids relocating object_id with `removed` gone."""
        return object_id == self.object_id and (self.removed is None or self.removed == frozenset(removed))


ReplanAnswer = tuple[tuple[str, ...], float, int] | tuple[tuple[str, ...], float, int, str]  # (sequence, weight
# (Eq. 8), planner calls it cost[, a note: how the Q-Tree retrained on the remaining problem did, replan.relearn])
Replanner = Callable[[RemainingProblem, frozenset[Option]], "ReplanAnswer | str"]


@dataclass(frozen=True)
class ReplanRecord:
    """One re-plan: why, and what came of it (the sequence and its weight, the planner calls it cost, or why none)."""

    reason: str
    sequence: tuple[str, ...] | None
    weight: float | None
    calls: int
    failure: str = ""
    note: str = ""  # the retrained Q-Tree's outcome (replan.relearn), when asked for

    def to_dict(self) -> dict[str, Any]:
        """An entry of the result's (and report.json's) `replans`."""
        d: dict[str, Any] = {"reason": self.reason, "sequence": list(self.sequence) if self.sequence else None,
                             "weight": self.weight, "calls": self.calls}
        return {**d, **{k: v for k, v in (("failure", self.failure), ("note", self.note)) if v}}

    def line(self) -> str:
        """One line for the feedback: why, and the new sequence with its weight (or why there is none)."""
        got = f"{' '.join(self.sequence)} (weight {self.weight:.2f})" if self.sequence and self.weight is not None \
            else self.failure
        return f"re-plan: {self.reason} -> {got}" + (f" ({self.note})" if self.note else "")


@dataclass(frozen=True)
class Step:
    """One relocation and its check: the object, the removed list it was sent with, the slot planned, the motion
    planner's outcome and the verification (None when the relocation failed)."""

    index: int
    object_id: str
    removed: tuple[str, ...]
    slot: int
    ok: bool
    message: str
    verification: Verification | None

    def to_dict(self) -> dict[str, Any]:
        """For the feedback and the result."""
        return {"index": self.index, "object": self.object_id, "removed": list(self.removed), "slot": self.slot,
                "ok": self.ok, "message": self.message,
                "verification": self.verification.to_dict() if self.verification else None}

    def line(self) -> str:
        """One line for the feedback: the check after this relocation, or why it failed."""
        what = self.verification.summary() if self.verification else f"relocating {self.object_id} failed: " \
            f"{self.message}"
        return f"check {self.index + 1}: {what}"


@dataclass
class ExecutionResult:
    """The outcome: success only when the target was seen on the bottom shelf (or, with a camera that does not see
    it, relocated and gone from the top shelf); one-line message; the steps
    (relocations tried), the re-plans, the objects relocated (verified, in order) and the new objects seen on the
    way, one line each ('new object u3 (box, 0.31 kg est.) at (0.84, 0.12) after relocating o2: re-planned')."""

    success: bool = False
    message: str = ""
    relocated: list[str] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)
    replans: list[ReplanRecord] = field(default_factory=list)
    unverified: list[str] = field(default_factory=list)  # relocated, but no scene showed where they stand
    new_objects: list[str] = field(default_factory=list)
    pushes: list[PushRecord] = field(default_factory=list)  # executed (executive.push)

    def to_dict(self) -> dict[str, Any]:
        """For the result and report.json (`replans`, `unverified`, `new_objects`, `pushes`)."""
        return {"success": self.success, "message": self.message, "relocated": list(self.relocated),
                "steps": [s.to_dict() for s in self.steps], "replans": [r.to_dict() for r in self.replans],
                "unverified": list(self.unverified), "new_objects": list(self.new_objects),
                "pushes": [p.to_dict() for p in self.pushes]}


class GiveUp(Exception):
    """The executor stops: no sequence remains (or cancelled, or the re-plan budget is spent); the one-line reason."""


class ClosedLoopExecutor:
    """Executes a relocation sequence, checking the world after each relocation and re-planning (module doc).

    relocate(object_id, removed) -> (ok, message): one relocation (removed: the verified relocations, in order;
    the motion planner's recovery brings the arm home and the bottle back on a failure). perceive() -> scene: a
    scene perceived after the call. replan(problem, banned) -> (sequence, weight, calls) or the reason there is
    none: a sequence for the RemainingProblem that uses no banned Option and at most len(problem.free_slots)
    slots. slot_of(problem) -> the slot index the next relocation goes to (default: the motion planner's rule,
    relocation_common.feasibility.destination_slot: slot len(removed), the one its certified answer planned the
    carry to, when it is free, else the first free one). on_step(step) after each relocation and
    on_replan(record) after each re-plan (feedback). action_cost: the remaining problems' obstacles costed by the
    pick their poses take (remaining_problem), else their weights.
    bottom_seen False: perception does not see the bottom shelf (verify_relocation); a relocated bottle that is
    not seen counts as relocated. perceive() raising ValueError, TimeoutError or RuntimeError (no scene) ends the
    run with its message. pusher (executive.push.Pusher; None: no pushes): when a re-plan proves that no sequence
    remains, the cheapest feasible push out of the proof's blocking cycle is executed (after the relocations of the
    objects it needs gone first, each verified), then the next scene is perceived and the rest re-planned from it
    (on_push(record) after each); an empty `sequence` to `run` (the first
    plan found none) starts with that re-plan.
    """

    def __init__(self, scenario: Scenario, relocate: Callable[[str, list[str]], tuple[bool, str]],
                 perceive: Callable[[], Scene], replan: Replanner, *, tolerances: Tolerances | None = None,
                 max_replans: int = 20, max_attempts: int = 2, cancelled: Callable[[], bool] = lambda: False,
                 on_step: Callable[[Step], None] = lambda step: None,
                 on_replan: Callable[[ReplanRecord], None] = lambda record: None,
                 slot_of: Callable[[RemainingProblem], int] | None = None, bottom_seen: bool = True,
                 on_progress: Callable[[ExecutionResult], None] = lambda result: None,
                 action_cost: ActionCosts | None = None, pusher: Pusher | None = None,
                 on_push: Callable[[PushRecord], None] = lambda record: None) -> None:
        if max_replans < 0 or max_attempts < 1:
            raise ValueError(f"need max_replans >= 0 and max_attempts >= 1, got {max_replans}, {max_attempts}")
        self.scenario, self.relocate, self.perceive, self.replan = scenario, relocate, perceive, replan
        self.tol, self.max_replans, self.max_attempts = tolerances or configured(), max_replans, max_attempts
        self.cancelled, self.on_step, self.on_replan = cancelled, on_step, on_replan
        self.slot_of = slot_of
        self.bottom_seen = bottom_seen
        self.on_progress = on_progress
        self.action_cost = action_cost
        self.pusher, self.on_push = pusher, on_push

    def run(self, sequence: Iterable[str], scene: Scene | None = None, relocated: Iterable[str] = ()
            ) -> ExecutionResult:
        """Relocate `sequence` (obstacles, then the target) starting from `scene` (default: perceive()); the
        result says whether the target reached the bottom shelf and, if not, why in one line. `relocated`: the
        relocations done before this run (a goal sent again to a respawned task planner: executive.resume), kept
        as relocated while the scene does not show them on the top shelf, and sent as removed."""
        out = ExecutionResult(relocated=list(relocated))
        self._banned: set[Option] = set()
        self._failures: dict[str, int] = {}
        self._retried: dict[tuple[str, frozenset[str]], int] = {}  # failures of time per option
        self._top: set[str] = set()  # every object seen resting on the top shelf during the run
        try:
            self._run(list(sequence), dict(scene if scene is not None else self._perceive("at the start")), out)
        except _Done:
            pass
        except GiveUp as e:
            out.success, out.message = False, str(e)
        return out

    def _run(self, seq: list[str], scene: dict[str, SeenObject], out: ExecutionResult) -> None:
        rp = self._problem(scene, out)
        problem = rp.problem
        assert problem is not None
        why = check_capacity(seq, len(rp.free_slots))
        if not seq:
            seq, scene, rp = self._replan(NONE_AT_START, scene, rp, out)
        elif why:
            seq, scene, rp = self._replan(f"capacity: {why}", scene, rp, out)
        elif _invalid(seq, problem):
            seq, scene, rp = self._replan(f"the sequence does not fit the scene: {_invalid(seq, problem)}", scene, rp,
                                          out)
        while True:
            scene, rp, why = self._relocate(seq[0], scene, rp, out)
            if why is None:
                seq = seq[1:]
                continue
            seq, scene, rp = self._replan(why, scene, rp, out)

    def _relocate(self, obj: str, scene: dict[str, SeenObject], rp: RemainingProblem, out: ExecutionResult
                  ) -> tuple[dict[str, SeenObject], RemainingProblem, str | None]:
        """Relocate `obj`, perceive and check the scene after it: (that scene, its remaining problem, None when the
        world is as planned, else the reason to re-plan, one line). A failed option is marked (`_fail`)."""
        if self.cancelled():
            raise GiveUp(f"cancelled after relocating {out.relocated}")
        if not rp.free_slots:
            raise GiveUp(f"no free slot on the bottom shelf for {obj}")
        # the relocated bottles, then those seen off the top shelf otherwise (dropped to the floor): the motion
        # planner keeps an unseen bottle at its last pose, and the re-plan's answers had them gone (rp.gone)
        removed, gone = tuple(out.relocated) + tuple(sorted(o for o in rp.gone if o in scene and o in self._top
                                                            and o not in out.relocated)), rp.gone
        slot = self.slot_of(rp) if self.slot_of else destination_slot(len(removed), rp.free_slots)
        ok, message = self.relocate(obj, list(removed))
        after = self._perceive(f"after relocating {obj}")
        check = None
        if ok or message.endswith(OUTCOME_UNKNOWN):  # unknown: the motion planner saw no scene, we look
            x, y = self.scenario.slots[slot]
            check = verify_relocation(obj, (x, y, self.scenario.shelf.bottom_z), scene, after, self.tol,
                                      self.bottom_seen)
            check = replace(check, new=self._on_top(check.new, after))
            if not ok and check.ok:
                ok, message = True, f"{message}; the scene after it shows it done"
        stayed, new = _stayed(obj, scene, after, self.tol), self._on_top(new_objects(scene, after, obj), after)
        if ok and check is not None and check.unseen_place:
            out.unverified.append(obj)
        step = Step(len(out.steps), obj, removed, slot, ok, message, check)
        out.steps.append(step)
        self.on_step(step)
        landed = after.get(obj)
        if (board_of(landed, self.scenario, self.tol) == "bottom" if landed is not None else
                ok and not self.bottom_seen):
            out.relocated.append(obj)
        self.on_progress(out)
        rp = self._problem(after, out)
        if check is not None and check.ok and not new:
            return after, rp, None
        out.new_objects += [f"{d.line} after relocating {obj}: re-planned" for d in new]
        if not ok:
            if stayed:  # the option failed; else the bottle was dropped or knocked: the re-plan asks about its
                self._fail(obj, gone, message)  # new pose (a bottle on the bottom shelf is relocated, above)
            return after, rp, f"relocating {obj} failed: {message}"
        assert check is not None  # a new object is no fault of the relocation: the rest is re-planned
        return after, rp, (f"the world differs after relocating {obj}: {check.summary()}" if not check.ok
                           else "; ".join(d.line for d in new))

    def _on_top(self, new: tuple[Difference, ...], scene: Scene) -> tuple[Difference, ...]:
        """The new objects that rest on the top shelf: an object first seen elsewhere (a relocated bottle the
        camera glimpses on the bottom shelf, as perception names it anew) is no obstacle and no re-plan."""
        return tuple(d for d in new if board_of(scene[d.object_id], self.scenario, self.tol) == "top")

    def _perceive(self, when: str) -> dict[str, SeenObject]:
        try:
            return dict(self.perceive())
        except (ValueError, TimeoutError, RuntimeError) as e:
            raise GiveUp(f"no scene {when}: {e}") from None

    def _problem(self, scene: Scene, out: ExecutionResult) -> RemainingProblem:
        """The remaining problem; stops the run when the target is on the bottom shelf (success) or out of reach.
        A relocated bottle seen back on the top shelf is no longer relocated (the motion planner must see it)."""
        out.relocated[:] = [o for o in out.relocated
                            if o not in scene or board_of(scene[o], self.scenario, self.tol) != "top"]
        rp = remaining_problem(self.scenario, scene, out.relocated, self.tol, self.action_cost)
        self._top |= {b.id for b in rp.bottles}  # an object off the top shelf is sent as removed only if it was on it
        # ... in the feasibility questions too: an unlisted object never seen on the top shelf (perception's glimpse
        # of the carried bottle or the hand, named anew) is one the motion planner never had, and it refuses the
        # question ("unknown object id 'u2'"), which ended the run; and an unlisted object no longer in the scene
        # (perception named it anew: the motion planner dropped it, scene_update's "superseded") is not gone either:
        # the planner has dropped it or keeps it at its last pose, an obstacle (sent removed, it asked "unknown
        # object id 'u1'" on world/crowd_20)
        rp = replace(rp, gone=frozenset(o for o in rp.gone if self._sent_as_gone(o, scene, out)))
        if rp.target_retrieved:
            out.success = True
            k, n = len(out.pushes), len(out.replans)
            out.message = (f"target {self.scenario.target_id} retrieved after {len(out.relocated) - 1} relocations"
                           + (f", {k} push{'es' * (k != 1)}" if k else "")
                           + (f" and {n} re-plan{'s' * (n != 1)}" if n else "")
                           + (" (it left the top shelf; its place on the bottom shelf was not seen: unverified)"
                              if self.scenario.target_id in out.unverified else ""))
            raise _Done
        if rp.problem is None:
            raise GiveUp(rp.reason)
        return rp

    def _sent_as_gone(self, oid: str, scene: Scene, out: ExecutionResult) -> bool:
        """Whether an object off the top shelf goes to the motion planner as removed: a listed one always; an
        unlisted one once seen on the top shelf and now relocated or seen elsewhere (not one perception renamed)."""
        listed = oid in self.scenario.ids and self.scenario.world_object(oid).listed
        return listed or oid in self._top and (oid in scene or oid in out.relocated)

    def _fail(self, obj: str, removed: frozenset[str], message: str = "") -> None:
        """Mark the failed option; an object failing max_attempts times is banned with any set. A failure of time
        (TRANSIENT: the planner's safety net, the follower under load) says nothing about the option: it is tried
        again, up to TRANSIENT_TRIES times in all, before it is marked."""
        if any(w in message for w in TRANSIENT):
            self._retried[(obj, removed)] = tries = self._retried.get((obj, removed), 0) + 1
            if tries < TRANSIENT_TRIES:
                return
        self._failures[obj] = self._failures.get(obj, 0) + 1
        self._banned.add(Option(obj, None if self._failures[obj] >= self.max_attempts else removed))

    def _replan(self, reason: str, scene: dict[str, SeenObject], rp: RemainingProblem, out: ExecutionResult
                ) -> tuple[list[str], dict[str, SeenObject], RemainingProblem]:
        """(a new sequence for `rp`, the scene and the remaining problem it is for), or GiveUp with the reason in
        one line. When no sequence remains, a push out of the proof's blocking cycle (`pusher`), then the scene
        after it re-planned, as often as pushes are executed."""
        while True:
            answer = self._solve(reason, rp, out)
            if not isinstance(answer, str):
                return answer, scene, rp
            pushed = self._push(scene, rp, out) if self.pusher is not None else None
            if pushed is None or isinstance(pushed, str):
                tried = self._tried(out, pushed)
                if not out.steps and not out.pushes and reason == NONE_AT_START:
                    raise GiveUp(f"the target cannot be retrieved: {answer}{tried}")
                raise GiveUp(f"no sequence remains: {answer} (re-planned because {reason}){tried}")
            scene, rp, reason = pushed

    def _push(self, scene: dict[str, SeenObject], rp: RemainingProblem, out: ExecutionResult
              ) -> tuple[dict[str, SeenObject], RemainingProblem, str] | str:
        """The cheapest feasible push (executive.push.Pusher), its prep relocations done (each verified; when one
        fails or the world differs, (the scene after it, its problem, why) to re-plan from), then the push executed,
        and (the scene after it, its remaining problem, the push's line as the next re-plan's reason); or why no push
        was executed."""
        assert self.pusher is not None and rp.problem is not None
        if self.cancelled():
            raise GiveUp(f"cancelled after relocating {out.relocated}")
        choice = self.pusher.choose(rp, {b.id: b.weight for b in rp.bottles}, rp.problem.costs, rp.gone,
                                    frozenset(self._banned))
        if isinstance(choice, str):
            return choice
        for i, obj in enumerate(choice.prep):
            scene, rp, why = self._relocate(obj, scene, rp, out)
            if why is not None:
                return scene, rp, f"{why} (relocating {', '.join(choice.prep[:i + 1])} to free the push of " \
                    f"{choice.object_id} out of {choice.clear_for}'s lanes)"
        if self.cancelled():
            raise GiveUp(f"cancelled after relocating {out.relocated}")
        got = self.pusher.run(choice, rp.gone)
        after = self._perceive(f"after pushing {got.object_id}")
        now = after.get(got.object_id)
        seen = (now.x, now.y) if now is not None and board_of(now, self.scenario, self.tol) == "top" else None
        got = replace(got, seen=seen)
        if _stayed(got.object_id, scene, after, self.tol):  # failed, or "done" and nothing moved: not asked again
            self.pusher.failed(got.object_id, got.clear_for)
        out.pushes.append(got)
        self.on_push(got)
        self.on_progress(out)
        return after, self._problem(after, out), got.what()

    @staticmethod
    def _tried(out: ExecutionResult, why: str | None) -> str:
        """What the "no sequence" end adds about pushes: those executed, and why no further one ("" without a
        pusher)."""
        if why is None:
            return ""
        done = f"; pushes executed: {'; '.join(p.line() for p in out.pushes)}" if out.pushes else ""
        return f"{done}; no {'further ' * bool(out.pushes)}push: {why}"

    def _solve(self, reason: str, rp: RemainingProblem, out: ExecutionResult) -> list[str] | str:
        """A new sequence for `rp` (recorded in out.replans), the proof's one-line reason there is none, or GiveUp
        (the re-plan budget, a sequence that cannot be executed)."""
        if len(out.replans) >= self.max_replans:
            raise GiveUp(f"gave up after {len(out.replans)} re-plans (max_replans); last: {reason}")
        # a bottle tipped over is asked about like any other (no ban of its own): the motion planner answers its
        # grasp from above where the headroom allows, else "no grasp: " with the headroom it needs
        answer = self.replan(rp, frozenset(self._banned))
        again = {b for b in self._banned if self._failures.get(b.object_id, 0) < self.max_attempts}
        if isinstance(answer, str) and again:  # no sequence avoids them: give up only when none remains at all
            retry = self.replan(rp, frozenset(self._banned - again))
            if not isinstance(retry, str):
                self._banned -= again
                answer, reason = retry, f"{reason}; no sequence avoids the failed option" + \
                    f"{'s' * (len(again) != 1)} of {', '.join(sorted({b.object_id for b in again}))}: tried again"
        if isinstance(answer, str):
            out.replans.append(ReplanRecord(reason, None, None, 0, answer))
            self.on_replan(out.replans[-1])
            self.on_progress(out)
            return answer
        seq, weight, calls, *note = answer
        problem = rp.problem
        assert problem is not None
        bad = (check_capacity(seq, len(rp.free_slots)) or _invalid(seq, problem)
               or next((f"it relocates {o} again, a failed option" for o, s in _options(seq, rp.gone)
                        if any(b.bans(o, s) for b in self._banned)), None))
        out.replans.append(ReplanRecord(reason, tuple(seq), weight, calls, f"refused: {bad}" if bad else "",
                                        note[0] if note else ""))
        self.on_replan(out.replans[-1])
        self.on_progress(out)
        if bad:
            raise GiveUp(f"the re-planner proposed a sequence that cannot be executed: {bad}")
        return list(seq)


NONE_AT_START = "the first plan found no sequence"  # the reason of the re-plan `run` starts with for an empty sequence
TRANSIENT = ("safety net", "did not settle", "tracking error", "stalled at", "no joint state from the driver",
             "restarted during this relocation")  # the motion planner's words for a relocation that ran out of time
# (budget.SafetyNetTimeout, execution.TrajectoryFollower, a driver starved under load) or that its restart
# interrupted (service.MotionPlannerService._resumed_outcome), not one that cannot be done
TRANSIENT_TRIES = 3  # relocations of one option that ran out of time before it is marked (a demo under load: twice)


class _Done(GiveUp):
    """The target is on the bottom shelf."""


def _stayed(obj: str, before: Scene, after: Scene, tol: Tolerances) -> bool:
    """True when `obj` rests where it rested before a failed relocation (within tol.still, standing or lying as it
    was): the failure is the option's (no grasp, no path) and the option is marked; a bottle moved or tipped by the
    attempt is not."""
    was, now = before.get(obj), after.get(obj)
    return was is not None and now is not None and (now.tilt > tol.tilt) == (was.tilt > tol.tilt) and \
        math.hypot(now.x - was.x, now.y - was.y) <= tol.still and abs(_support(now) - _support(was)) <= tol.board


def _options(seq: Iterable[str], gone: frozenset[str]) -> Iterator[tuple[str, frozenset[str]]]:
    """(object, removed set) of each relocation of `seq` after `gone`."""
    removed = set(gone)
    for o in seq:
        yield o, frozenset(removed)
        removed.add(o)


def _invalid(seq: Sequence[str], problem: RelocationProblem) -> str | None:
    """Why `seq` is not a retrieval sequence of `problem` (obstacles of it, once each, then its target), or None."""
    if not seq or seq[-1] != problem.target:
        return f"it does not end with the target {problem.target}"
    body = seq[:-1]
    unknown = [o for o in body if o not in problem.weights]
    if unknown or len(set(body)) != len(body):
        return f"it names {', '.join(unknown)} not on the top shelf" if unknown else "it relocates an object twice"
    return None
