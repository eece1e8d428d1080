"""The perceived world against the plan, ROS-free: the scene as the closed loop reads it, its tolerances, the check
after each relocation and the retrieval problem left in a scene (docs/closed_loop.md).

After each relocation a scene perceived after it ended is checked against the plan (`verify_relocation`: the moved
bottle on the bottom shelf at its slot, every other bottle where it was, the target present); a new object (one present
now and absent before: a hidden object revealed behind the relocated one, or an object the scenario does not list seen
for the first time; `new_objects`) is no difference but a reason to re-plan. The remaining retrieval problem is built
from the perceived scene (`remaining_problem`: relocated bottles out, moved ones at their new poses, newly seen ones
in). The free slots of the bottom shelf bound every sequence (`check_capacity`). The executor that uses all this:
`executive.closed_loop`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from qtree_task_planner.problem import ActionCosts, ProblemError, RelocationProblem
from relocation_common.config import ParameterError, node_section
from relocation_common.feasibility import pick_action
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


def support_of(o: SeenObject) -> float:
    """Height of the surface the object rests on (relocation_common.shelf_object.support_height)."""
    return support_height(o.z, o.radius, o.tilt)


def board_of(o: SeenObject, scenario: Scenario, tol: Tolerances) -> str | None:
    """'top' or 'bottom' when the object rests on that board of the shelf, standing or lying, else None: its
    support within tol.board of the board, its footprint's centre over it (Shelf.board_of, the motion planner's
    rule)."""
    return scenario.shelf.board_of(o.footprint().centre, support_of(o), tol.board)


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
    relocated, `board_of`, but not as planned: a difference that says so; one that lay before it was relocated may
    lie there, its footprint's centre on the slot: the grasp along its axis places it so); every other object of
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
        was = before_scene.get(planned_object)
        if abs(support_of(moved) - sz) <= tol.board and moved.tilt > tol.tilt and was is not None and \
                was.tilt > tol.tilt:  # it lay before: placed lying (the grasp along its axis), its footprint's centre
            at = moved.footprint().centre
            if math.dist(at, (sx, sy)) > tol.slot:
                diffs.append(Difference("not_at_slot", planned_object, f"{planned_object} lies on the bottom shelf "
                                        f"{100 * math.dist(at, (sx, sy)):.1f} cm from its slot ({sx:.3f}, {sy:.3f})"))
        elif abs(support_of(moved) - sz) <= tol.board and moved.tilt > tol.tilt:  # relocated, but lying: not as planned
            at = moved.footprint().centre
            diffs.append(Difference("not_at_slot", planned_object, f"{planned_object} tipped over on the bottom shelf "
                                    f"({math.degrees(moved.tilt):.0f} deg), lying {100 * math.dist(at, (sx, sy)):.1f} "
                                    f"cm from its slot ({sx:.3f}, {sy:.3f})"))
        elif abs(support_of(moved) - sz) > tol.board or moved.tilt > tol.tilt:
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
        if now is None and not bottom_seen and abs(support_of(was) - sz) <= tol.board:
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
        elif d > tol.still or abs(support_of(now) - support_of(was)) > tol.board:
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
                       weight_note=o.weight_note, support_z=support_of(o))


def check_capacity(sequence: Iterable[str], free: int) -> str | None:
    """Why `sequence` cannot be executed with `free` free slots (every relocated object, the target included, takes
    one), or None when it fits."""
    n = len(tuple(sequence))
    if n > free:
        return f"the sequence relocates {n} objects but only {free} slot{'s' * (free != 1)} of the bottom shelf " \
               f"{'are' if free != 1 else 'is'} free"
    return None
