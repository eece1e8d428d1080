"""Scenario files: the one loader of shelf, objects, weights, target, slots and marker (config/scenarios/*.yaml).

Every part of the system (task planner, motion planner, simulator, perception) reads a scene through
`load_scenario`. Frames: everything is in the robot base frame (x forward to the shelf, z up, metres).
The format is documented in docs/scenarios.md; the object model (ShelfObject) is relocation_common.shelf_object's.

Where an object rests, and which slots of the bottom shelf are free, is one rule for every caller (the motion
planner's destination, stpik_motion_planner.execution.goal_check, and the task planner's free slots,
qtree_task_planner.executive.closed_loop, read a scene through these, so that they agree on every scene):
`Shelf.board_of`: an object rests on a board when its lowest point is within a tolerance of the board's surface and
the centre of its footprint is over the board (a lying bottle's base centre is a radius above its board and its end
face half its length from its footprint's centre: neither says where it lies). `Scenario.free_slots`: a slot is
taken when the widest listed object standing on it at any turn (`slot_radius`) would overlap the footprint of an
object on the bottom shelf (ShelfObject.footprint: a standing bottle's circle, a lying bottle's or a box's rectangle).
"""
from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping

from .config import ConfigError, read_yaml, short
from .paths import default_scenario, resolve_scenario
from .shelf_object import DECIMALS, SHAPES, Footprint, ShelfObject, estimated_weight, half_turn, unlisted_density

__all__ = ["PALETTE", "TARGET_COLOR", "TARGET_RGB", "Marker", "Scenario", "ScenarioError", "Shelf", "ShelfObject",
           "UnknownObjectError", "load_scenario", "parse_scenario"]

# Named colours of the objects (the paper's bottles were coloured; perception tells objects apart by colour, among
# other things). Objects without a `color:` take these in turn, round again after the last. The target is green,
# as in the paper's experiment. RGB in [0, 1].
PALETTE: dict[str, tuple[float, float, float]] = {
    "red": (0.85, 0.10, 0.10),
    "blue": (0.10, 0.25, 0.90),
    "yellow": (0.95, 0.85, 0.10),
    "magenta": (0.85, 0.10, 0.80),
    "cyan": (0.10, 0.80, 0.85),
    "orange": (0.95, 0.50, 0.05),
    "purple": (0.45, 0.15, 0.70),
    "white": (0.92, 0.92, 0.92),
    "black": (0.08, 0.08, 0.08),
    "brown": (0.50, 0.30, 0.12),
    "pink": (0.98, 0.60, 0.75),
    "navy": (0.05, 0.05, 0.40),
    "olive": (0.50, 0.50, 0.05),
    "teal": (0.02, 0.45, 0.45),
    "maroon": (0.45, 0.02, 0.05),
    "gray": (0.50, 0.50, 0.50),
}
TARGET_COLOR = "green"
TOP, BOTTOM = "top", "bottom"  # Shelf.board_of's boards
TARGET_RGB = (0.10, 0.75, 0.15)


class ScenarioError(ConfigError):
    """A scenario file or dict that cannot be used; the message says what to fix."""


class UnknownObjectError(KeyError):
    """An object id that is not in the scenario."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else "unknown object"


@dataclass(frozen=True)
class Shelf:
    """Shelf unit open towards the robot (-x side). Heights are board top surfaces; ceiling is an underside."""

    x_front: float
    depth: float
    width: float
    y_center: float
    board_thickness: float
    top_z: float
    ceiling_z: float
    bottom_z: float

    @property
    def x_back(self) -> float:
        """Back edge of the shelf (m)."""
        return self.x_front + self.depth

    @property
    def y_min(self) -> float:
        """Smallest y of the shelf (m)."""
        return self.y_center - self.width / 2

    @property
    def y_max(self) -> float:
        """Largest y of the shelf (m)."""
        return self.y_center + self.width / 2

    def board_of(self, centre: tuple[float, float], support: float, tolerance: float) -> str | None:
        """TOP or BOTTOM when an object whose footprint is centred at `centre` (x, y) and whose lowest point is at
        height `support` rests on that board, standing or lying (within `tolerance` m of its surface, its centre
        over the board: the module docstring), else None (lifted, fallen, off the shelf)."""
        x, y = centre
        if not (self.x_front <= x <= self.x_back and self.y_min <= y <= self.y_max):
            return None
        if abs(support - self.top_z) <= tolerance:
            return TOP
        return BOTTOM if abs(support - self.bottom_z) <= tolerance else None


@dataclass(frozen=True)
class Marker:
    """ArUco marker on the shelf: OpenCV convention (z out of the face, x right, y up as seen from the front)."""

    id: int
    dictionary: str
    size: float
    position: tuple[float, float, float]
    rpy: tuple[float, float, float]


@dataclass(frozen=True)
class Scenario:
    """A relocation scene: the shelf, its listed objects (one the target), the free slots and the ArUco marker;
    `unlisted`, the objects only the simulator builds (the planners and perception never read them)."""

    name: str
    description: str
    shelf: Shelf
    objects: tuple[ShelfObject, ...]
    target_id: str
    slots: tuple[tuple[float, float], ...]
    marker: Marker
    blocking: Mapping[str, frozenset[str]] | None = None
    source: str = "<dict>"
    auto_slots: bool = False  # slots from `slots: auto` (AUTO_SLOT_*); the motion planner checks them at start
    more_markers: tuple[Marker, ...] = ()  # the further markers of `markers:` (optional)
    unlisted: tuple[ShelfObject, ...] = ()  # `unlisted:` (listed False): the simulator's world only
    _by_id: dict[str, ShelfObject] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._by_id.update({o.id: o for o in self.objects})

    @property
    def ids(self) -> tuple[str, ...]:
        """Ids of every object, target included, in file order."""
        return tuple(o.id for o in self.objects)

    @property
    def obstacle_ids(self) -> tuple[str, ...]:
        """Ids of the obstacles (every object but the target), in file order."""
        return tuple(o.id for o in self.objects if not o.is_target)

    @property
    def weights(self) -> dict[str, float]:
        """phi_i of every obstacle (Eq. 8, 13). The target's weight does not enter the reward."""
        return {o.id: o.weight for o in self.objects if not o.is_target}

    @property
    def world(self) -> tuple[ShelfObject, ...]:
        """Every object the simulator builds: the listed ones, then the unlisted ones."""
        return self.objects + self.unlisted

    def world_object(self, object_id: str) -> ShelfObject:
        """The object `object_id`, listed or unlisted (the simulator's view); UnknownObjectError names them all."""
        for o in self.world:
            if o.id == object_id:
                return o
        raise UnknownObjectError(f"unknown object id {object_id!r} in scenario {self.name!r}; known ids: "
                                 f"{', '.join(o.id for o in self.world)}")

    @property
    def slot_note(self) -> str:
        """'' or one line: `slots: auto` found room for fewer slots than there are objects."""
        if not self.auto_slots or len(self.slots) >= len(self.objects):
            return ""
        return (f"slots: auto lays out {len(self.slots)} slots on this bottom shelf for {len(self.objects)} objects: "
                f"a retrieval relocating more than {len(self.slots)} is refused (list the slots, or widen the shelf)")

    def object(self, object_id: str) -> ShelfObject:
        """The listed object `object_id`; UnknownObjectError names the known ids."""
        try:
            return self._by_id[object_id]
        except KeyError:
            raise UnknownObjectError(
                f"unknown object id {object_id!r} in scenario {self.name!r}; known ids: {', '.join(self.ids)}"
            ) from None

    def check_ids(self, ids: Iterable[str]) -> frozenset[str]:
        """Return ids as a frozenset, raising UnknownObjectError naming the first id not in the scenario."""
        ids = frozenset(ids)
        for i in sorted(ids):
            self.object(i)
        return ids

    def with_objects(self, objects: Iterable[ShelfObject]) -> "Scenario":
        """The same shelf, slots and marker with another set of objects (e.g. as perceived, unlisted ones
        included); validated: one target, distinct ids. It may hold more objects than slots: the closed loop
        refuses a sequence that relocates more than the free slots take (check_capacity)."""
        objects = tuple(objects)
        targets = [b.id for b in objects if b.is_target]
        if len(targets) != 1:
            raise ScenarioError(f"{self.name}: a scene needs exactly one target, got {len(targets)}")
        ids = [b.id for b in objects]
        if len(set(ids)) != len(ids):
            raise ScenarioError(f"{self.name}: duplicate object ids")
        return Scenario(self.name, self.description, self.shelf, objects, targets[0], self.slots,
                        self.marker, None, self.source, self.auto_slots, self.more_markers, self.unlisted)

    @property
    def markers(self) -> tuple[Marker, ...]:
        """Every ArUco marker on the shelf: `marker` first, then the further ones of `markers:`."""
        return (self.marker, *self.more_markers)

    @property
    def slot_radius(self) -> float:
        """The room an object placed in a slot takes about the slot: the widest listed object standing, at any turn
        (ShelfObject.upright_radius; the same for the scenario file and a scene of it, `with_objects`, as perceived
        by ground truth)."""
        return max((o.upright_radius for o in self.objects if o.listed), default=0.0)

    def free_slots(self, below: Iterable[Footprint]) -> tuple[int, ...]:
        """Indices of the slots that no footprint of `below` (the objects on the bottom shelf) overlaps within
        `slot_radius` of the slot (the module docstring)."""
        taken, r = list(below), self.slot_radius
        return tuple(k for k, xy in enumerate(self.slots) if not any(f.overlaps(Footprint(xy, r, ())) for f in taken))

    def slot(self, n_relocated: int) -> tuple[float, float]:
        """Destination on the bottom shelf of the object relocated after n_relocated others (fills in order)."""
        if not 0 <= n_relocated < len(self.slots):
            raise ValueError(f"no slot {n_relocated}: the scenario has {len(self.slots)} slots")
        return self.slots[n_relocated]


# Object ids name MuJoCo bodies (MJCF), ROS messages and log lines: letters, digits, underscore.
ID_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}")
# Scenario names: as ids, plus '-' and '.' (never first: no hidden or relative file names)
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
# OpenCV's predefined ArUco dictionaries (cv2.aruco.DICT_*), named here so the loader need not import OpenCV.
ARUCO_DICTIONARIES = tuple(f"DICT_{n}X{n}_{k}" for n in (4, 5, 6, 7) for k in (50, 100, 250, 1000)) + (
    "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10", "DICT_APRILTAG_36h11",
    "DICT_ARUCO_MIP_36h12")


def _num(d: Mapping[str, Any], key: str, where: str, default: float | None = None) -> float:
    """A finite number, from `d` or (checked the same way) the default."""
    v = d.get(key, default) if isinstance(d, Mapping) else None
    if v is None:
        raise ScenarioError(f"{where}: missing required key {key!r}")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ScenarioError(f"{where}: {key} must be a finite number, got {short(v)}")
    return float(v)


def _marker_id(m: Mapping[str, Any]) -> int:
    v = _num(m, "id", "marker")
    if not v.is_integer() or not 0 <= v < 1024:
        raise ScenarioError(f"marker: id must be an integer in [0, 1024), got {short(m.get('id'))}")
    return int(v)


def _dictionary(m: Mapping[str, Any]) -> str:
    d = m.get("dictionary", "DICT_4X4_50")
    if d not in ARUCO_DICTIONARIES:
        raise ScenarioError(f"marker: dictionary must be one of OpenCV's (e.g. DICT_4X4_50), got {short(d)}")
    return d


def _vec(d: Mapping[str, Any], key: str, n: int, where: str, default: Any = None) -> tuple[float, ...]:
    v = d.get(key, default)
    if v is None:
        raise ScenarioError(f"{where}: missing required key {key!r}")
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise ScenarioError(f"{where}: {key} must be a list of {n} numbers, got {short(v)}")
    return tuple(_num({key: x}, key, where) for x in v)


def _vec2(d: Mapping[str, Any], key: str, where: str) -> tuple[float, float]:
    x, y = _vec(d, key, 2, where)
    return x, y


def _vec3(d: Mapping[str, Any], key: str, where: str) -> tuple[float, float, float]:
    x, y, z = _vec(d, key, 3, where)
    return x, y, z


def _shelf(d: Any) -> Shelf:
    if not isinstance(d, Mapping):
        raise ScenarioError("shelf: must be a mapping")
    s = Shelf(
        x_front=_num(d, "x_front", "shelf"),
        depth=_num(d, "depth", "shelf"),
        width=_num(d, "width", "shelf"),
        y_center=_num(d, "y_center", "shelf", 0.0),
        board_thickness=_num(d, "board_thickness", "shelf", 0.02),
        top_z=_num(d, "top_z", "shelf"),
        ceiling_z=_num(d, "ceiling_z", "shelf"),
        bottom_z=_num(d, "bottom_z", "shelf"),
    )
    if s.depth <= 0 or s.width <= 0 or s.board_thickness <= 0:
        raise ScenarioError("shelf: depth, width and board_thickness must be positive")
    if not s.bottom_z + s.board_thickness < s.top_z - s.board_thickness < s.top_z < s.ceiling_z:
        raise ScenarioError("shelf: need bottom_z < top_z < ceiling_z with room for the boards")
    return s


# `slots: auto`: the layout of paper_experiment_10's explicit slots, which the arm reaches, derived from the shelf.
# Two rows on the bottom shelf, AUTO_SLOT_ROWS behind its front edge, back row first so that a placement never reaches
# past a placed bottle; in a row the central slots first (the outer ones are near the edge of the arm's reach),
# AUTO_SLOT_SPACING apart so that the open hand fits between two bottles (hand 0.124 m wide: 25 mm to spare), and
# at least AUTO_SLOT_WALL from a side panel (the open fingers reach 0.062 m beside the bottle's axis). A 0.80 m wide
# shelf holds 12; a scene with more objects gets 12 (a relocation beyond the last slot is refused).
# The motion planner checks at start that every auto slot is within the arm's reach (MotionPlanner, WorkspaceError).
AUTO_SLOT_ROWS = (0.14, 0.06)  # m behind x_front: back row, front row
AUTO_SLOT_SPACING = 0.12  # m between neighbours in a row
AUTO_SLOT_WALL = 0.09  # m from a slot's axis to a side panel, at least


def _default_slots(shelf: Shelf, n: int) -> tuple[tuple[float, float], ...]:
    """Up to n slots (see AUTO_SLOT_ROWS): rows that fit in the shelf's depth, positions symmetric about y_center."""
    half = shelf.width / 2 - AUTO_SLOT_WALL
    dys: list[float] = []
    j = 0
    while (j + 0.5) * AUTO_SLOT_SPACING <= half + 1e-9:
        dys += [-(j + 0.5) * AUTO_SLOT_SPACING, (j + 0.5) * AUTO_SLOT_SPACING]
        j += 1
    if not dys and half >= 0:  # too narrow for two: one central column
        dys = [0.0]
    rows = [shelf.x_front + r for r in AUTO_SLOT_ROWS if shelf.x_front + r <= shelf.x_back - 0.06]
    return tuple((round(x, 6), round(shelf.y_center + dy, 6)) for x in rows for dy in dys)[:n]


def parse_scenario(data: Any, source: str = "<dict>") -> Scenario:
    """Validate a scenario mapping (as read from YAML) and build a Scenario; ScenarioError on any problem."""
    if not isinstance(data, Mapping):
        raise ScenarioError(f"{source}: a scenario must be a YAML mapping, got {type(data).__name__}")
    try:
        return _parse(data, source)
    except ScenarioError as e:
        raise ScenarioError(f"{source}: {e}") from None


SCENARIO_KEYS = ("name", "description", "shelf", "defaults", "target", "objects", "unlisted", "slots", "marker",
                 "markers", "blocking")


def _parse(data: Mapping[str, Any], source: str) -> Scenario:
    shelf = _shelf(data.get("shelf"))
    target_id = data.get("target")
    if not isinstance(target_id, str) or not target_id:
        raise ScenarioError("target: missing; name the id of the object to retrieve")
    unknown = sorted(set(map(str, data)) - set(SCENARIO_KEYS))
    if unknown:
        raise ScenarioError(f"unknown key(s) {', '.join(unknown)}; a scenario has {', '.join(SCENARIO_KEYS)}")
    objects, unlisted = _objects(data, shelf, target_id)
    slots, auto = _slots(data.get("slots", "auto"), shelf, len(objects))
    markers = _markers(data)
    return Scenario(
        name=_name(data, source),
        description=str(data.get("description", "")),
        shelf=shelf,
        objects=objects,
        target_id=target_id,
        slots=slots,
        marker=markers[0],
        blocking=_blocking(data, {o.id for o in objects}),
        source=source,
        auto_slots=auto,
        more_markers=markers[1:],
        unlisted=unlisted,
    )


def _name(data: Mapping[str, Any], source: str) -> str:
    """The scenario's name (`name`, else the file's name without .yaml): it names a MuJoCo model, files of the
    evaluation's caches, graphs and log lines, so it is checked like an id (NAME_PATTERN). A scene given as data
    (source "<dict>") without a name is "unnamed"."""
    name = data.get("name", "unnamed" if source.startswith("<") else Path(source).stem)  # "<dict>": no file
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        where = "name" if "name" in data else f"name (from the file name {Path(source).name!r}: give a `name:`)"
        raise ScenarioError(f"{where}: must be a letter or digit then up to 63 letters, digits, '_', '-' or '.', "
                            f"got {short(name)}")
    return name


OBJECT_KEYS = ("id", "weight", "xy", "shape", "radius", "height", "size", "yaw", "lying", "color")
Palette = Iterator[tuple[str, tuple[float, float, float]]]


def _objects(data: Mapping[str, Any], shelf: Shelf, target_id: str
             ) -> tuple[tuple[ShelfObject, ...], tuple[ShelfObject, ...]]:
    """(listed, unlisted): ids, weights, shapes (or `defaults`), colours; on the top shelf, under the ceiling, no
    two footprints overlapping (listed and unlisted alike)."""
    defaults = data.get("defaults", {}) or {}
    if not isinstance(defaults, Mapping):
        raise ScenarioError("defaults: must be a mapping")
    size = (_num(defaults, "radius", "defaults", 0.033), _num(defaults, "height", "defaults", 0.16))
    raw = data.get("objects")
    if not isinstance(raw, list) or not raw:
        raise ScenarioError("objects: must be a non-empty list")
    extra = data.get("unlisted", [])
    if not isinstance(extra, list):
        raise ScenarioError("unlisted: must be a list of objects (the format of `objects:`)")
    raw_ids = [o.get("id") for o in raw if isinstance(o, Mapping)]
    if target_id not in raw_ids:
        raise ScenarioError(f"target: {target_id!r} is not among the objects ({', '.join(map(str, raw_ids))})")
    palette = itertools.cycle(PALETTE.items())  # objects without `color:` take the colours in turn, round again
    out: list[ShelfObject] = []
    for section, items in (("objects", raw), ("unlisted", extra)):
        for k, o in enumerate(items):
            b = _object(o, f"{section}[{k}]", shelf, target_id, size, palette, section == "objects")
            if any(b.id == other.id for other in out):
                raise ScenarioError(f"{section}[{k}]: duplicate id {b.id!r}")
            out.append(b)
    prints = [o.footprint() for o in out]
    for i, a in enumerate(out):
        for j in range(i + 1, len(out)):
            if prints[i].overlaps(prints[j]):
                raise ScenarioError(f"objects {a.id!r} and {out[j].id!r} overlap")
    return tuple(o for o in out if o.listed), tuple(o for o in out if not o.listed)


def _object(o: Any, where: str, shelf: Shelf, target_id: str, size: tuple[float, float], palette: Palette,
            listed: bool) -> ShelfObject:
    """One entry of `objects:` (listed) or `unlisted:`, validated; resting on the top shelf."""
    if not isinstance(o, Mapping):
        raise ScenarioError(f"{where}: must be a mapping")
    oid = o.get("id")
    if not isinstance(oid, str) or not ID_PATTERN.fullmatch(oid):
        raise ScenarioError(f"{where}: id must be a letter then up to 31 letters, digits or underscores, "
                            f"got {short(oid)}")
    where = f"{where} ({oid})"
    unknown = sorted(set(map(str, o)) - set(OBJECT_KEYS))
    if unknown:
        raise ScenarioError(f"{where}: unknown key(s) {', '.join(unknown)}; an object has {', '.join(OBJECT_KEYS)}")
    is_target = oid == target_id
    if is_target and not listed:
        raise ScenarioError(f"{where}: the target must be listed in `objects:`")
    x, y = _vec(o, "xy", 2, where)
    label, rgb = _color(o, where, is_target, palette)
    radius, height, shape, dims, yaw, lying = _shape(o, where, size)
    b = ShelfObject(oid, label, rgb, 1.0, x, y, radius, height, is_target, shape, dims, yaw, lying, listed,
                    support_z=shelf.top_z)
    if not is_target and ("weight" in o or listed):
        weight = _num(o, "weight", where)
        if not 0.0 < weight <= 1.0:
            raise ScenarioError(f"{where}: weight must be in (0, 1], got {weight}")
        b = replace(b, weight=weight)
    elif not is_target:  # an unlisted object nobody weighed: as perception would estimate it
        weight, note = estimated_weight(b, unlisted_density())
        b = replace(b, weight=weight, weight_note=note)
    if not b.footprint().inside(shelf.x_front, shelf.x_back, shelf.y_min, shelf.y_max):
        raise ScenarioError(f"{where}: xy {x, y} is not on the top shelf")
    if b.top_z - shelf.top_z >= shelf.ceiling_z - shelf.top_z:
        raise ScenarioError(f"{where}: height {b.top_z - shelf.top_z:g} does not fit under the ceiling board")
    return b


def _color(o: Mapping[str, Any], where: str, is_target: bool, palette: Palette
           ) -> tuple[str, tuple[float, float, float]]:
    """(label, rgb): `color:` a PALETTE name or [r, g, b] in [0, 1] (labelled with the name of an equal palette
    colour, else ""); the target without one is green; any other object takes the palette's next colour."""
    c = o.get("color")
    if c is None:
        return (TARGET_COLOR, TARGET_RGB) if is_target else next(palette)
    if isinstance(c, str):
        if c == TARGET_COLOR:
            return TARGET_COLOR, TARGET_RGB
        if c not in PALETTE:
            raise ScenarioError(f"{where}: unknown color {short(c)}; use one of {', '.join(PALETTE)}, "
                                f"{TARGET_COLOR} or [r, g, b]")
        return c, PALETTE[c]
    r, g, b = _vec(o, "color", 3, where)
    if not all(0.0 <= v <= 1.0 for v in (r, g, b)):
        raise ScenarioError(f"{where}: color [r, g, b] must be in [0, 1], got {[r, g, b]}")
    named = {**PALETTE, TARGET_COLOR: TARGET_RGB}
    return next((k for k, v in named.items() if v == (r, g, b)), ""), (r, g, b)


def _shape(o: Mapping[str, Any], where: str, size: tuple[float, float]
           ) -> tuple[float, float, str, tuple[float, float, float], float, bool]:
    """(radius, height, shape, size, yaw, lying) of an entry: a cylinder standing
    (radius, height) or lying (yaw of its axis), or a box (size, yaw)."""
    shape = o.get("shape", "cylinder")
    if shape not in SHAPES:
        raise ScenarioError(f"{where}: shape must be one of {', '.join(SHAPES)}, got {short(shape)}")
    lying = o.get("lying", False)
    if not isinstance(lying, bool):
        raise ScenarioError(f"{where}: lying must be true or false, got {short(lying)}")
    yaw = _num(o, "yaw", where, 0.0)
    if shape == "box":
        if "radius" in o or "height" in o or lying:
            raise ScenarioError(f"{where}: a box has `size: [sx, sy, sz]` and `yaw`, not radius, height or lying")
        sx, sy, sz = _vec3(o, "size", where)
        if min(sx, sy, sz) <= 0:
            raise ScenarioError(f"{where}: size must be three positive numbers, got {[sx, sy, sz]}")
        return 0.0, sz, "box", (sx, sy, sz), _turned(yaw), False
    if "size" in o:
        raise ScenarioError(f"{where}: a cylinder has radius and height, not size (or give `shape: box`)")
    if "yaw" in o and not lying:
        raise ScenarioError(f"{where}: yaw turns a box or a lying cylinder; a standing cylinder has none")
    radius, height = _num(o, "radius", where, size[0]), _num(o, "height", where, size[1])
    if radius <= 0 or height <= 0:
        raise ScenarioError(f"{where}: radius and height must be positive")
    return radius, height, "cylinder", (0.0, 0.0, 0.0), _turned(yaw) if lying else 0.0, lying


def _turned(yaw: float) -> float:
    """A file's yaw in (-pi/2, pi/2], rounded as a measured one is (DECIMALS): a box at 1.601 rad survives the
    message round trip (-1.540592654 both ways)."""
    return round(half_turn(yaw), DECIMALS)


def _slots(raw: Any, shelf: Shelf, n: int) -> tuple[tuple[tuple[float, float], ...], bool]:
    """(slots, whether they were laid out automatically)."""
    if raw == "auto":
        slots = _default_slots(shelf, n)
        if not slots:
            raise ScenarioError("slots: 'auto' finds no room on this bottom shelf; list the slots")
        return slots, True
    if isinstance(raw, list) and len(raw) >= n:
        return tuple(_vec2({"xy": s}, "xy", f"slots[{k}]") for k, s in enumerate(raw)), False
    raise ScenarioError(f"slots: 'auto' or a list of at least {n} [x, y] positions")


def _markers(data: Mapping[str, Any]) -> tuple[Marker, ...]:
    """`marker:` (the main one) and the optional list `markers:` of further markers (several across the shelf front,
    so one covered marker does not lose the frame); ids distinct."""
    ms = data.get("markers", [])
    if not isinstance(ms, list):
        raise ScenarioError("markers: must be a list of further markers (id, dictionary, size, position, rpy)")
    out = [_marker(data.get("marker"))]
    for k, m in enumerate(ms):
        try:
            out.append(_marker(m))
        except ScenarioError as e:
            raise ScenarioError(f"markers[{k}]: {e}") from None
    ids = [(m.dictionary, m.id) for m in out]
    if len(set(ids)) != len(ids):
        raise ScenarioError(f"markers: ids must be distinct, got {[m.id for m in out]}")
    return tuple(out)


def _marker(m: Any) -> Marker:
    if not isinstance(m, Mapping):
        raise ScenarioError("marker: missing; give id, dictionary, size, position, rpy of the ArUco marker")
    return Marker(id=_marker_id(m), dictionary=_dictionary(m), size=_num(m, "size", "marker"),
                  position=_vec3(m, "position", "marker"), rpy=_vec3(m, "rpy", "marker"))


def _blocking(data: Mapping[str, Any], ids: set[str]) -> dict[str, frozenset[str]] | None:
    """The declared blocking relation (tests only), or None."""
    if "blocking" not in data:
        return None
    b = data["blocking"]
    if not isinstance(b, Mapping):
        raise ScenarioError("blocking: must map an id to the list of ids that must be removed first")
    blocking = {}
    for oid, needs in b.items():
        if oid not in ids:
            raise ScenarioError(f"blocking: unknown id {short(oid)}")
        if not isinstance(needs, list) or any(not isinstance(n, str) or n not in ids for n in needs):
            raise ScenarioError(f"blocking[{oid}]: must be a list of known ids, got {short(needs)}")
        blocking[oid] = frozenset(needs)
    return blocking


def load_scenario(path: str | Path | None = None) -> Scenario:
    """Read and validate a scenario YAML file: a path, a name under config/scenarios, or None for the default
    scene. Raises ScenarioError with a one-line reason."""
    path = resolve_scenario(path) if path is not None else default_scenario()
    data = read_yaml(path, ScenarioError, "scenario file")
    return parse_scenario(data, str(path))
