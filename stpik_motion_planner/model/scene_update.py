"""The planner's scene from perception: which perceived bottles replace the planner's (ROS-free).

Perception sees the bottles on the top shelf; the planner keeps the scenario's shelf and slots and its last pose
of every bottle. A perceived bottle (not the one being carried) resting on the top shelf (its support within
ON_SHELF of the board, inside its edges) replaces the planner's when it moved more than MOVED or changed how it
rests: standing (its axis within UPRIGHT_TILT of the vertical), lying flat (tipped over: its axis within the planner's
`flat_tilt` of horizontal, as a measured pose never is exactly; `laid_flat` makes it the lying ShelfObject a scenario
gives, which the grasp from above takes where the headroom allows), or leaning (neither: an obstacle as the cylinder
it is, never graspable). A bottle seen below the bottom board or outside the shelf below the top board left the
shelf (dropped to the floor): gone from the scene, no obstacle. Bottles on the bottom shelf (relocated), lifted or
not seen keep their last pose (hidden behind others, or in the hand).

Objects the scenario does not list (`listed` false: perception found them, or the simulator's ground truth carries
them) enter the scene like any other, as the primitive they are. One that is no longer in a scene which holds
another object where it stood (its footprint overlapped) is dropped: perception named it anew, and kept, it would
be a phantom obstacle no relocation removes. One left out of `phantom_scenes` scenes in a row
(config/motion_planner.yaml; the scenes that count: no relocation running, the object's place in view, `in_view`)
is dropped too: perception no longer sees it where nothing could hide it (perception itself holds an unseen object
at its last pose for its hold_frames first).
Otherwise, hidden behind another object, it keeps its last pose, as a listed bottle always does (the task planner's
closed loop reasons about every listed one); so does an object this node placed on the bottom shelf (`kept`).
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Collection, Iterable, Mapping, NamedTuple

import numpy as np

from relocation_common.geometry import quat_wxyz, wxyz_matrix
from relocation_common.scenario import TOP, Shelf, ShelfObject
from relocation_common.shelf_object import DECIMALS, UPRIGHT_TILT, Footprint, half_turn
from stpik_motion_planner.model.collision import Lying

MOVED = 0.003  # m: a perceived bottle this far from the planner's scene replaces it
ON_SHELF = 0.01  # m: a bottle whose support is farther from the top shelf's surface is lifted or elsewhere


class Merged(NamedTuple):
    """The planner's scene after a perceived one: every object (the scenario's and the unlisted ones seen), the lying
    ones, the ones gone from the shelf, the ids that changed, the ids seen resting on the top shelf, and how many
    counted scenes in a row have left out each unlisted object still kept (the next merge's `missing`)."""

    bottles: dict[str, ShelfObject]
    lying: dict[str, Lying]
    gone: frozenset[str]
    changed: list[str]
    seen: set[str]
    missing: dict[str, int]


def _inside(shelf: Shelf, bottle: ShelfObject) -> bool:
    return shelf.x_front < bottle.x < shelf.x_back and shelf.y_min < bottle.y < shelf.y_max


def _support(bottle: ShelfObject) -> float:
    if bottle.support_z is None:
        raise ValueError(f"perceived object {bottle.id!r} has no support_z")
    return bottle.support_z


def on_top_shelf(shelf: Shelf, bottle: ShelfObject) -> bool:
    """True if `bottle` (as perceived: its support_z) rests on the top shelf, within its edges (standing or
    lying: Shelf.board_of, the rule of the goal checks and of the task planner)."""
    return shelf.board_of((bottle.x, bottle.y), _support(bottle), ON_SHELF) == TOP


def left_the_shelf(shelf: Shelf, bottle: ShelfObject) -> bool:
    """True if `bottle` rests below the bottom board, or outside the shelf below the top board: dropped."""
    s = _support(bottle)
    return s < shelf.bottom_z - ON_SHELF or (not _inside(shelf, bottle) and s < shelf.top_z - ON_SHELF)


def laid_flat(bottle: ShelfObject, flat_tilt: float) -> ShelfObject:
    """A perceived cylinder lying with its axis within `flat_tilt` (rad) of horizontal as one lying exactly flat
    (`tilt` None, its axis's yaw modulo pi), about the same centre: its support one radius below it (its ends move
    by at most half its length times sin(flat_tilt)); any other object unchanged."""
    if bottle.shape != "cylinder" or not bottle.lying or bottle.tilt is None or \
            abs(bottle.tilt - math.pi / 2) > flat_tilt:
        return bottle
    z = float(bottle.centre()[2]) - bottle.radius
    return replace(bottle, tilt=None, yaw=round(half_turn(bottle.yaw), DECIMALS), support_z=round(z, DECIMALS))


def lying_pose(bottle: ShelfObject) -> Lying | None:
    """The collision model's pose of a bottle that leans (its axis more than UPRIGHT_TILT from the vertical, not
    lying flat): its base centre and orientation; None for a standing or a flat one (its ShelfObject models it)."""
    if bottle.axis_tilt <= UPRIGHT_TILT or (bottle.lying and bottle.tilt is None):
        return None
    w, x, y, z = quat_wxyz(bottle.rotation())
    bx, by, bz = (float(v) for v in bottle.base())
    return Lying((bx, by, bz), (w, x, y, z))


def merge_perceived(shelf: Shelf, current: Mapping[str, ShelfObject], perceived: Iterable[ShelfObject],
                    flat_tilt: float, held: str | None = None, lying: Mapping[str, Lying] | None = None,
                    gone: Iterable[str] = (), missing: Mapping[str, int] | None = None,
                    phantom_scenes: int | None = None, kept: Collection[str] = ()) -> Merged:
    """The planner's scene (`current` bottles, the leaning ones in `lying`, the `gone` ones) after the `perceived`
    objects (as relocation_common.ros_conversions.msg_to_objects gives them; `flat_tilt`: laid_flat's); `held`: the
    bottle being carried, ignored, and the scene no count of `missing` (module docstring); `phantom_scenes` None: this
    scene counts for none (a scene received again); `kept`: ids never dropped by the count."""
    bottles, lying, gone = dict(current), dict(lying or {}), set(gone)
    changed, seen = [], set()
    perceived = list(perceived)
    vanished, missing = _vanished(shelf, current, perceived, gone, dict(missing or {}),
                                  phantom_scenes if held is None else None, set(kept))
    for i in sorted(set(_superseded(shelf, current, perceived, gone)) | set(vanished)):
        changed.append(i)
        del bottles[i]
        lying.pop(i, None)
    for b in (laid_flat(b, flat_tilt) for b in perceived):
        i = b.id
        if i == held:
            continue
        if on_top_shelf(shelf, b):
            seen.add(i)
            now = lying_pose(b)
            if _differs(current.get(i), b, lying.get(i), now) or i in gone:
                changed.append(i)
                bottles[i] = b
                gone.discard(i)
                if now is None:
                    lying.pop(i, None)
                else:
                    lying[i] = now
        elif left_the_shelf(shelf, b) and i not in gone:
            changed.append(i)
            gone.add(i)
            lying.pop(i, None)
    return Merged(bottles, lying, frozenset(gone), sorted(changed), seen, missing)


def _superseded(shelf: Shelf, current: Mapping[str, ShelfObject], perceived: list[ShelfObject],
                gone: Iterable[str]) -> list[str]:
    """The unlisted objects of `current` (still on the shelf) that `perceived` does not hold while it holds another
    object on the same board whose footprint overlaps theirs (the module docstring)."""
    ids, gone = {b.id for b in perceived}, set(gone)
    out = []
    for i, o in current.items():
        if o.listed or i in ids or i in gone:
            continue
        mine, board = o.footprint(), shelf.top_z if o.support_z is None else o.support_z
        if any(abs(_support(b) - board) < ON_SHELF and b.footprint().overlaps(mine) for b in perceived):
            out.append(i)
    return out


def _vanished(shelf: Shelf, current: Mapping[str, ShelfObject], perceived: list[ShelfObject], gone: set[str],
              missing: dict[str, int], phantom_scenes: int | None, kept: set[str]) -> tuple[list[str], dict[str, int]]:
    """(the unlisted objects to drop, the counts after this scene): each unlisted object of `current` resting on the
    top shelf that `perceived` leaves out while its place is in view (`in_view`) counts this scene; one counted
    `phantom_scenes` times in a row is dropped. Seen again, its count ends; hidden (or `phantom_scenes` None: a scene
    that counts for none), its count stays."""
    ids = {b.id for b in perceived}
    counts = {i: n for i, n in missing.items() if i in current and i not in ids and i not in gone}
    if phantom_scenes is None:
        return [], counts
    others = [b for b in perceived if on_top_shelf(shelf, b)] + [
        o for i, o in current.items() if i not in ids and i not in gone and _rests_on_top(shelf, o)]
    out = []
    for i, o in current.items():
        if o.listed or i in ids or i in gone or i in kept or not _rests_on_top(shelf, o) or \
                not in_view(shelf, o, [b for b in others if b.id != i]):
            continue
        counts[i] = counts.get(i, 0) + 1
        if counts[i] >= phantom_scenes:
            out.append(i)
            del counts[i]
    return out, counts


def _rests_on_top(shelf: Shelf, o: ShelfObject) -> bool:
    """The planner's object rests on the top shelf (a scenario object without support_z stands there)."""
    return o.support_z is None or abs(o.support_z - shelf.top_z) < ON_SHELF


def in_view(shelf: Shelf, o: ShelfObject, others: Iterable[ShelfObject]) -> bool:
    """True when no object of `others` stands between `o` and the shelf's open front within o's width: a camera
    looks into the shelf from its front, and nothing there can hide it (one in front may: then it is not in view)."""
    f = o.footprint()
    ys = [c[1] for c in f.corners] or [f.centre[1] - f.radius, f.centre[1] + f.radius]
    lo, hi = min(ys), max(ys)
    corridor = Footprint(((shelf.x_front + o.x) / 2, (lo + hi) / 2), 0.0,
                         ((shelf.x_front, lo), (o.x, lo), (o.x, hi), (shelf.x_front, hi)))
    return not any(b.footprint().overlaps(corridor) for b in others)


def _differs(was: ShelfObject | None, now: ShelfObject, was_lying: Lying | None, now_lying: Lying | None) -> bool:
    """A perceived bottle differs from the planner's: new, moved more than MOVED, or standing <-> lying flat <->
    leaning, or leaning otherwise (its top moved more than MOVED); a box or a flat lying cylinder also turned so that
    the corners of its footprint moved more than MOVED (the faces the side grasp takes a box by and the axis the grasp
    from above closes across turn with it)."""
    if was is None or was.lying != now.lying or (was_lying is None) != (now_lying is None):
        return True
    if was_lying is not None and now_lying is not None:
        return math.dist(_top(was_lying, now.height), _top(now_lying, now.height)) > MOVED or \
            math.dist(was_lying.base, now_lying.base) > MOVED
    a, b = np.asarray(now.footprint().corners), np.asarray(was.footprint().corners)
    if len(a) and len(b):  # each corner of its footprint to the nearest of the planner's
        if float(np.max(np.min(np.linalg.norm(a[:, None] - b[None], axis=2), axis=1))) > MOVED:
            return True
    return math.hypot(now.x - was.x, now.y - was.y) > MOVED


def _top(pose: Lying, height: float) -> tuple[float, ...]:
    """The centre of a lying bottle's top face."""
    axis = wxyz_matrix(pose.quat)[:, 2]
    return tuple(float(c + a * height) for c, a in zip(pose.base, axis))
