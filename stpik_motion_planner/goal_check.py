"""A RelocateObject goal checked against the scene, and its outcome checked after the motion (ROS-free).

The task planner's `removed_ids` is what it believes (Sect. 4.2: the objects relocated so far); the scene (the
driver's ground truth or perception) is what is. Before the motion: a removed bottle that still stands on the top
shelf, or a goal object that already stands on the bottom shelf, refuses the goal with the reason (planning with a
bottle that is there as if it were gone knocks it over). The destination is a free slot of the bottom shelf: slots
occupied by a bottle of the scene, or by one this node placed and the scene does not show, are skipped. After the
motion: the moved bottle stands at its slot (when the scene shows it; perception sees the top shelf only) and no
other bottle moved more than the tolerance; otherwise the relocation is not a success and the result says what
moved (docs/reliability.md, "What a relocation reports").
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

from relocation_common.scenario import Shelf

ON_BOARD = 0.01  # m: a bottle whose base is this close to a board's surface stands on it (scene_update.ON_SHELF)


@dataclass(frozen=True)
class SeenBottle:
    """A bottle of the scene: (x, y) of its frame, z of its base (ObjectState.pose), base frame, metres."""

    id: str
    x: float
    y: float
    z: float


def _inside(shelf: Shelf, b: SeenBottle) -> bool:
    return shelf.x_front < b.x < shelf.x_back and shelf.y_min < b.y < shelf.y_max


def on_top_shelf(shelf: Shelf, b: SeenBottle) -> bool:
    """Standing on the top shelf's board (as scene_update.on_top_shelf)."""
    return abs(b.z - shelf.top_z) < ON_BOARD and _inside(shelf, b)


def on_bottom_shelf(shelf: Shelf, b: SeenBottle) -> bool:
    """Standing on the bottom shelf's board: relocated."""
    return abs(b.z - shelf.bottom_z) < ON_BOARD and _inside(shelf, b)


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


def placed_bottles(shelf: Shelf, slots: Sequence[tuple[float, float]], seen: Mapping[str, SeenBottle],
                   relocated: Mapping[str, int]) -> list[tuple[str, tuple[float, float]]]:
    """(id, (x, y)) of the bottles on the bottom shelf: as the scene shows them, else where this node put them."""
    placed = [(i, (b.x, b.y)) for i, b in seen.items() if on_bottom_shelf(shelf, b)]
    shown = {i for i, _ in placed}
    placed += [(i, slots[k]) for i, k in relocated.items() if i not in shown and i not in seen and k < len(slots)]
    return sorted(placed)


def free_slot(slots: Sequence[tuple[float, float]], placed: Sequence[tuple[str, tuple[float, float]]],
              clearance: float) -> int:
    """The first slot with no placed bottle's axis within `clearance` (two radii: the bottles would touch).
    ValueError when every slot is taken."""
    for k, (x, y) in enumerate(slots):
        if all(math.hypot(x - px, y - py) >= clearance for _, (px, py) in placed):
            return k
    taken = ", ".join(i for i, _ in placed)
    raise ValueError(f"no free slot on the bottom shelf: all {len(slots)} slots are taken ({taken})")


def outcome_problems(shelf: Shelf, before: Mapping[str, SeenBottle], after: Mapping[str, SeenBottle],
                     object_id: str, slot: tuple[float, float], tolerance: float, slot_tolerance: float) -> list[str]:
    """What is wrong after relocating object_id to `slot` (empty: the relocation did what it says). Bottles in
    both scenes that moved more than `tolerance` (m, 3D); the moved bottle farther than `slot_tolerance` from the
    slot on the bottom shelf (when `after` shows it), or still on the top shelf."""
    problems = []
    b = after.get(object_id)
    if b is not None:
        off = math.dist((b.x, b.y, b.z), (slot[0], slot[1], shelf.bottom_z))
        if on_top_shelf(shelf, b):
            problems.append(f"{object_id} is still on the top shelf")
        elif off > slot_tolerance:
            problems.append(f"{object_id} is {off * 1000:.0f} mm from its slot ({slot[0]:.3f}, {slot[1]:.3f})")
    for i in sorted(set(before) & set(after) - {object_id}):
        p, q = before[i], after[i]
        d = math.dist((p.x, p.y, p.z), (q.x, q.y, q.z))
        if d > tolerance:
            fell = " (no longer standing on its board)" if abs(q.z - p.z) > ON_BOARD else ""
            problems.append(f"{i} moved {d * 1000:.0f} mm{fell}")
    return problems


PARAMETERS = ("outcome_tolerance", "slot_tolerance", "outcome_timeout")  # config/motion_planner.yaml


def check_parameters(values: Mapping[str, float]) -> None:
    """ValueError naming a parameter of PARAMETERS that is not a positive number."""
    for k in PARAMETERS:
        v = values[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:  # also NaN
            raise ValueError(f"parameter {k} must be > 0, got {v!r}")
