"""The planner's scene from perception: which perceived bottles replace the planner's (ROS-free).

Perception sees the bottles that stand on the top shelf; the planner keeps the scenario's shelf and slots and its
last pose of every bottle. A perceived bottle replaces the planner's when it stands on the top shelf (its base
within ON_SHELF of the board), is not the one being carried, and moved more than MOVED; bottles not seen keep
their last pose (hidden behind others, or lifted).
"""
from __future__ import annotations

import math
from typing import Mapping

from relocation_common.scenario import Bottle, Shelf

MOVED = 0.003  # m: a perceived bottle this far from the planner's scene replaces it
ON_SHELF = 0.01  # m: a bottle whose base is farther from the top shelf's surface is lifted or elsewhere


def on_top_shelf(shelf: Shelf, bottle: Bottle, base_z: float) -> bool:
    """True if `bottle` (its base at `base_z`) stands on the top shelf, within its edges."""
    return (abs(base_z - shelf.top_z) < ON_SHELF and shelf.x_front < bottle.x < shelf.x_back
            and shelf.y_min < bottle.y < shelf.y_max)


def merge_perceived(shelf: Shelf, current: Mapping[str, Bottle], perceived, held: str | None = None
                    ) -> tuple[dict[str, Bottle], list[str], set[str]]:
    """(merged bottles, ids that changed, ids seen on the top shelf) from `perceived` = (bottle, base z) pairs."""
    on_top = {b.id: b for b, z in perceived if b.id != held and on_top_shelf(shelf, b, z)}
    changed = sorted(i for i, b in on_top.items() if i not in current
                     or math.hypot(b.x - current[i].x, b.y - current[i].y) > MOVED)
    return {**current, **{i: on_top[i] for i in changed}}, changed, set(on_top)
