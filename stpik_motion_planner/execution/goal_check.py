"""A RelocateObject goal checked against the scene, and its outcome checked after the motion (ROS-free).

The task planner's `removed_ids` is what it believes (Sect. 4.2: the objects relocated so far); the scene (the
driver's ground truth or perception) is what is. Before the motion: a removed bottle that still stands on the top
shelf, or a goal object that already stands on the bottom shelf, refuses the goal with the reason (planning with a
bottle that is there as if it were gone knocks it over). The destination is a free slot of the bottom shelf: slots
taken by an object of the scene resting there, standing or lying (its footprint; the rule the task planner's free
slots read too: relocation_common.scenario, Shelf.board_of and Scenario.free_slots), or by one this node placed and
the scene does not show, are skipped; slot len(removed), the one a certified feasible answer planned the carry to,
when it is free (docs/motion_planner.md, "The certified slot"). After the
motion: the moved bottle stands at its slot (when the scene shows it; perception sees the top shelf only) and no
other bottle moved more than the tolerance; otherwise the relocation is not a success and the result says what
moved (a bottle that tipped over on the bottom shelf is relocated but not placed as asked: not a success, said so);
with no scene after the motion, the outcome is unknown, never a success (docs/reliability.md, "Never report
success that is not true").
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Iterable, Mapping, Sequence

from relocation_common.feasibility import OUTCOME_UNKNOWN, destination_slot
from relocation_common.scenario import BOTTOM, TOP, Scenario, ScenarioError, Shelf, ShelfObject, UnknownObjectError
from relocation_common.shelf_object import UPRIGHT_TILT, Footprint
from stpik_motion_planner.planning.params import node_parameters

ON_BOARD = 0.01  # m: an object whose lowest point is this close to a board rests on it (scene_update.ON_SHELF)
OUTCOME_SETTLE = 0.3  # s after the motion: the scene that shows the outcome is received after this (bottles settled)


Point = tuple[float, float, float]  # an object's base centre (base frame, m): what `outcome_problems` compares


@dataclass(frozen=True)
class SeenBottle:
    """An object of the scene (base frame, metres): `x, y, z` the centre of its base (ShelfObject.base: a lying
    bottle's lower end face), `support` the height of its lowest point, `tilt` its axis from the vertical (rad), and
    its `footprint` on the board it rests on (`seen_bottle`)."""

    id: str
    x: float
    y: float
    z: float
    support: float
    tilt: float
    footprint: Footprint

    @property
    def point(self) -> Point:
        """Its base centre."""
        return self.x, self.y, self.z


def seen_bottle(o: ShelfObject) -> SeenBottle:
    """A perceived object (ros_conversions.msg_to_objects: its support_z set) as the checks read it."""
    x, y, z = (float(v) for v in o.base())
    if o.support_z is None:
        raise ValueError(f"object {o.id!r} of the scene has no support_z")
    return SeenBottle(o.id, x, y, z, o.support_z, o.axis_tilt, o.footprint())


class SceneWatch:
    """The last scene a node received, whole, and when (monotonic clock): what the goal and outcome checks read."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.seen: dict[str, SeenBottle] = {}
        self.at = -math.inf
        self._clock = clock

    def update(self, objects: Iterable[ShelfObject]) -> None:
        """A new scene: its objects as perceived (checked by scene_check first)."""
        self.seen, self.at = {o.id: seen_bottle(o) for o in objects}, self._clock()

    def after(self, t: float, timeout: float, ok: Callable[[], bool] = lambda: True) -> dict[str, SeenBottle] | None:
        """The first scene received after clock time t; None after `timeout` s or once ok() is false."""
        deadline = self._clock() + timeout
        while self.at < t:
            if self._clock() > deadline or not ok():
                return None
            time.sleep(0.02)
        return dict(self.seen)


def on_top_shelf(shelf: Shelf, b: SeenBottle) -> bool:
    """Resting on the top shelf's board, standing or lying (Shelf.board_of)."""
    return shelf.board_of(b.footprint.centre, b.support, ON_BOARD) == TOP


def on_bottom_shelf(shelf: Shelf, b: SeenBottle) -> bool:
    """Resting on the bottom shelf's board, standing or lying (tipped over there): relocated."""
    return shelf.board_of(b.footprint.centre, b.support, ON_BOARD) == BOTTOM


def refusal(shelf: Shelf, object_id: str, removed: Sequence[str], seen: Mapping[str, SeenBottle],
            relocated: Mapping[str, int]) -> str | None:
    """Why the goal (object_id, removed) contradicts the scene, or None. `relocated`: object -> slot, placed by
    this node."""
    standing = [i for i in removed if i in seen and on_top_shelf(shelf, seen[i])]
    if standing:
        where = ", ".join(f"{i} at ({seen[i].x:.3f}, {seen[i].y:.3f})" for i in standing)
        return (f"removed_ids lists {', '.join(standing)} but the scene shows {'it' if len(standing) == 1 else 'them'}"
                f" standing on the top shelf ({where}); relocate {'it' if len(standing) == 1 else 'them'} first or "
                "send the removed set the scene shows")
    b = seen.get(object_id)
    if b is not None and on_bottom_shelf(shelf, b):
        return f"{object_id!r} was already relocated: the scene shows it on the bottom shelf at ({b.x:.3f}, {b.y:.3f})"
    if object_id in relocated and not (b is not None and on_top_shelf(shelf, b)):
        return f"{object_id!r} was already relocated (to slot {relocated[object_id]})"
    return None


def goal_refusal(scenario: Scenario, object_id: str, removed: Sequence[str], seen: Mapping[str, SeenBottle],
                 relocated: Mapping[str, int]) -> str | None:
    """Why RelocateObject(object_id, removed) cannot be carried out, or None: unknown ids, the object in its own
    removed set, no free slot, or the scene contradicting the goal (`refusal`)."""
    try:
        scenario.object(object_id)
        if object_id in scenario.check_ids(removed):
            return f"{object_id!r} is in its own removed set"
        destination(scenario, seen, relocated, len(removed))
    except (UnknownObjectError, ScenarioError, ValueError) as e:
        return str(e)
    return refusal(scenario.shelf, object_id, removed, seen, relocated)


def destination(scenario: Scenario, seen: Mapping[str, SeenBottle], relocated: Mapping[str, int],
                n_removed: int) -> tuple[int, list[tuple[str, tuple[float, float]]]]:
    """(the slot, the objects on the bottom shelf: id and footprint centre) from the scene and what the node placed:
    slot `n_removed` (the goal's len(removed_ids): the slot a certified answer planned the carry to) when it is free,
    else the first free one (relocation_common.feasibility.destination_slot); a slot is free when no object's
    footprint comes within the widest object's radius of it (Scenario.free_slots, as the task planner counts them).
    ValueError when every slot is taken."""
    below = placed_bottles(scenario.shelf, scenario.slots, seen, relocated, scenario.slot_radius)
    placed = [(i, f.centre) for i, f in below]
    free = scenario.free_slots(f for _, f in below)
    if not free:
        taken = ", ".join(i for i, _ in placed)
        raise ValueError(f"no free slot on the bottom shelf: all {len(scenario.slots)} slots are taken ({taken})")
    return destination_slot(n_removed, free), placed


def placed_bottles(shelf: Shelf, slots: Sequence[tuple[float, float]], seen: Mapping[str, SeenBottle],
                   relocated: Mapping[str, int], radius: float) -> list[tuple[str, Footprint]]:
    """(id, footprint) of the objects on the bottom shelf, standing or lying: as the scene shows them, else where
    this node put them (a disc of `radius` about the slot)."""
    placed = [(i, b.footprint) for i, b in seen.items() if on_bottom_shelf(shelf, b)]
    shown = {i for i, _ in placed}
    placed += [(i, Footprint(slots[k], radius, ())) for i, k in relocated.items()
               if i not in shown and i not in seen and k < len(slots)]
    return sorted(placed, key=lambda p: p[0])


def outcome_problems(shelf: Shelf, before: Mapping[str, Point], after: Mapping[str, SeenBottle],
                     object_id: str, slot: tuple[float, float], tolerance: float, slot_tolerance: float) -> list[str]:
    """What is wrong after relocating object_id to `slot` (empty: the relocation did what it says). Objects in
    both scenes whose base centre (`before`: id -> it) moved more than `tolerance` (m, 3D); the moved bottle
    farther than `slot_tolerance` from the slot on the bottom shelf (when `after` shows it), tipped over there, or
    still on the top shelf. One that lay before (its base centre above its board: a cylinder lying) is placed lying
    by the grasp along its axis: on its slot when its footprint's centre is within `slot_tolerance` of it."""
    problems = []
    b = after.get(object_id)
    lay = object_id in before and before[object_id][2] > shelf.top_z + ON_BOARD
    if b is not None:
        off = math.dist(b.point, (slot[0], slot[1], shelf.bottom_z))
        if on_top_shelf(shelf, b):
            problems.append(f"{object_id} is still on the top shelf")
        elif on_bottom_shelf(shelf, b) and b.tilt > UPRIGHT_TILT and lay:
            off = math.dist(b.footprint.centre, slot)
            if off > slot_tolerance:
                problems.append(f"{object_id} lies {off * 1000:.0f} mm from its slot ({slot[0]:.3f}, {slot[1]:.3f})")
        elif on_bottom_shelf(shelf, b) and b.tilt > UPRIGHT_TILT:
            off = math.dist(b.footprint.centre, slot)
            problems.append(f"{object_id} tipped over on the bottom shelf ({math.degrees(b.tilt):.0f} deg), lying "
                            f"{off * 1000:.0f} mm from its slot ({slot[0]:.3f}, {slot[1]:.3f})")
        elif off > slot_tolerance:
            problems.append(f"{object_id} is {off * 1000:.0f} mm from its slot ({slot[0]:.3f}, {slot[1]:.3f})")
    for i in sorted(set(before) & set(after) - {object_id}):
        p, q = before[i], after[i].point
        d = math.dist(p, q)
        if d > tolerance:
            fell = " (no longer standing on its board)" if abs(q[2] - p[2]) > ON_BOARD else ""
            problems.append(f"{i} moved {d * 1000:.0f} mm{fell}")
    return problems


PARAMETERS = ("outcome_tolerance", "slot_tolerance", "outcome_timeout")  # config/motion_planner.yaml


def configured() -> dict[str, float]:
    """The PARAMETERS as config/motion_planner.yaml gives them (a core without a node), checked."""
    values = {k: v for k, v in node_parameters().items() if k in PARAMETERS}
    check_parameters(values)
    return {k: float(v) for k, v in values.items()}


def check_parameters(values: Mapping[str, float]) -> None:
    """ValueError naming a parameter of PARAMETERS that is not a positive number."""
    for k in PARAMETERS:
        v = values[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:  # also NaN
            raise ValueError(f"parameter {k} must be > 0, got {v!r}")


def outcome(watch: SceneWatch, before: Mapping[str, Point], scenario: Scenario, object_id: str, slot: int,
            values: Mapping[str, float], source: str, ok: Callable[[], bool] = lambda: True) -> tuple[bool, str]:
    """(success, result message) of a relocation whose motion just ended: the first scene received OUTCOME_SETTLE s
    later against `before` (each object's base centre; outcome_problems; `values`: the PARAMETERS). Success only
    after that look at the world: a scene that does not come within outcome_timeout (none at all, or the source
    silent: perception restarting) leaves the outcome unknown, not a success (the message ends with OUTCOME_UNKNOWN;
    the task planner looks at its own scene). Without a scene before the motion only the moved bottle is checked
    (the message says so)."""
    done = f"relocated {object_id} to slot {slot}"
    after = watch.after(time.monotonic() + OUTCOME_SETTLE, float(values["outcome_timeout"]), ok)
    if after is None:
        return False, f"{done}, but no scene on {source} within outcome_timeout after the motion: {OUTCOME_UNKNOWN}"
    problems = outcome_problems(scenario.shelf, before, after, object_id, scenario.slots[slot],
                                float(values["outcome_tolerance"]), float(values["slot_tolerance"]))
    if problems:
        return False, f"{done}, but the scene shows: {'; '.join(problems)}"
    return True, done + ("" if before else f" (the other bottles not checked: no scene on {source} before the motion)")
