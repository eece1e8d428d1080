"""Which board of the shelf an object rests on, and which slots of the bottom shelf are free: one rule for every caller.

The motion planner's destination (stpik_motion_planner.execution.goal_check) and the task planner's free slots
(qtree_task_planner.executive.closed_loop) both read a scene through these, so that they agree on every scene:

- `board_of`: an object rests on a board when its support (the height of its lowest point: ShelfObject.support_z,
  or `shelf_object.support_height` from a base centre and a tilt) is within `tolerance` of the board's surface and
  the centre of its footprint is over the board. A lying bottle's base centre is a radius above its board, and its
  end face is half its length from its footprint's centre: neither says where it lies.
- `free_slots`: a slot is taken when a disc of `slot_radius` about it (the widest object of the scenario standing
  there, at any turn) overlaps the footprint of an object on the bottom shelf (ShelfObject.footprint: a standing
  bottle's circle, a lying bottle's or a box's rectangle).
"""
from __future__ import annotations

import math
from typing import Iterable, Sequence

from .scenario import Shelf
from .shelf_object import Footprint, ShelfObject

TOP, BOTTOM = "top", "bottom"


def board_of(shelf: Shelf, centre: tuple[float, float], support: float, tolerance: float) -> str | None:
    """TOP or BOTTOM when an object whose footprint is centred at `centre` (x, y) and whose lowest point is at
    height `support` rests on that board (within `tolerance` m of its surface, its centre over the board), else
    None (lifted, fallen, off the shelf)."""
    x, y = centre
    if not (shelf.x_front <= x <= shelf.x_back and shelf.y_min <= y <= shelf.y_max):
        return None
    if abs(support - shelf.top_z) <= tolerance:
        return TOP
    if abs(support - shelf.bottom_z) <= tolerance:
        return BOTTOM
    return None


def upright_radius(o: ShelfObject) -> float:
    """Radius of the vertical cylinder about a standing object's centre that holds it at any turn about the
    vertical: a cylinder's radius, a box's half-diagonal (a box in its slot stands turned as the hand held it)."""
    return math.hypot(o.size[0], o.size[1]) / 2 if o.shape == "box" else o.radius


def slot_radius(objects: Iterable[ShelfObject]) -> float:
    """The room an object placed in a slot takes about the slot: the widest of `objects` standing, at any turn
    (`upright_radius`)."""
    return max((upright_radius(o) for o in objects), default=0.0)


def free_slots(slots: Sequence[tuple[float, float]], below: Iterable[Footprint], radius: float) -> tuple[int, ...]:
    """Indices of the `slots` that no footprint of `below` (the objects on the bottom shelf) overlaps within
    `radius` (slot_radius) of the slot."""
    taken = list(below)
    return tuple(k for k, slot in enumerate(slots) if not any(f.overlaps(Footprint(slot, radius, ())) for f in taken))
