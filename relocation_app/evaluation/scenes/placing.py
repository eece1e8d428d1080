"""Objects of the shelf as it is, drawn at free spots: their shapes (`Spec`: bottles of several sizes, jars, boxes,
a bottle lying), the test that a drawn object fits (`fits`), the uniform draw over the free part of the top shelf
(`place_uniform`, `uniform_layout`), the scenario entry of a placed object (`entry`), and the other layout, objects
slid into columns as a shelf is stocked (`stocked`, below). Used by world.py.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from relocation_app.evaluation.scenes.layout import MAX_REACH, SHELF, X_FREE, Y_FREE
from relocation_common.scenario import ShelfObject

GAP = 0.004  # m between two objects' footprints
DRAWS = 4000  # spots drawn per object before the layout is given up
MARKERS = {"marker": {"id": 7, "dictionary": "DICT_4X4_50", "size": 0.07, "position": [0.625, -0.345, 0.09],
                      "rpy": [1.5707963, 0.0, -1.5707963]},
           "markers": [{"id": 8, "dictionary": "DICT_4X4_50", "size": 0.07, "position": [0.625, 0.345, 0.09],
                        "rpy": [1.5707963, 0.0, -1.5707963]}]}  # paper_experiment_10's two markers


@dataclass(frozen=True)
class Spec:
    """One object of a recipe: a cylinder (radius, height; lying or standing) or a box (size)."""

    shape: str = "cylinder"
    radius: float = 0.033
    height: float = 0.16
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lying: bool = False

    def entry(self) -> dict[str, Any]:
        """The keys of a scenario entry that give this shape (none for the default bottle)."""
        if self.shape == "box":
            return {"shape": "box", "size": list(self.size)}
        out: dict[str, Any] = {}
        if self.radius != 0.033:
            out["radius"] = self.radius
        if self.height != 0.16:
            out["height"] = self.height
        if self.lying:
            out["lying"] = True
        return out

    @property
    def oriented(self) -> bool:
        """Whether its yaw matters (a box, a lying cylinder)."""
        return self.shape == "box" or self.lying


BOTTLE = Spec()
SLIM = Spec(radius=0.028)
SMALL = Spec(radius=0.025, height=0.12)
TALL = Spec(radius=0.03, height=0.2)
JAR = Spec(radius=0.04, height=0.09)  # wider than the open hand: never grasped
SHORT_JAR = Spec(radius=0.035, height=0.1)
LYING = Spec(lying=True)
BOX_A, BOX_B, BOX_C = Spec("box", size=(0.06, 0.09, 0.14)), Spec("box", size=(0.05, 0.05, 0.1)), \
    Spec("box", size=(0.08, 0.06, 0.18))


def shelf_object(spec: Spec, oid: str, x: float, y: float, yaw: float) -> ShelfObject:
    """The object `spec` standing (or lying) at (x, y) on the top shelf, its yaw kept only where it matters."""
    return ShelfObject(oid, "", (0.5, 0.5, 0.5), 0.5, x, y, 0.0 if spec.shape == "box" else spec.radius,
                       spec.height, False, spec.shape, spec.size, yaw if spec.oriented else 0.0,
                       spec.lying, support_z=SHELF["top_z"])


def fits(o: ShelfObject, placed: list[ShelfObject], reach: bool = True) -> bool:
    """On the top shelf (with `reach`: its centre within the arm's reach and |y| <= Y_FREE), GAP from every placed
    object."""
    s = SHELF
    if reach and (abs(o.y) > Y_FREE or math.hypot(o.x, o.y) > MAX_REACH):
        return False
    if not o.footprint().inside(s["x_front"], s["x_front"] + s["depth"], -s["width"] / 2 + GAP, s["width"] / 2 - GAP):
        return False
    grown = o.footprint(GAP)
    return not any(grown.overlaps(p.footprint()) for p in placed)


def place_uniform(rng: random.Random, spec: Spec, oid: str, placed: list[ShelfObject],
                  draw: Callable[[], tuple[float, float]] | None = None) -> ShelfObject | None:
    """`spec` at the first of DRAWS uniformly drawn spots (x in X_FREE, |y| <= Y_FREE, any yaw) that fits."""
    for _ in range(DRAWS):
        x, y = draw() if draw is not None else (rng.uniform(*X_FREE), rng.uniform(-Y_FREE, Y_FREE))
        o = shelf_object(spec, oid, round(x, 3), round(y, 3), round(rng.uniform(-math.pi / 2, math.pi / 2), 3))
        if fits(o, placed):
            placed.append(o)
            return o
    return None


def uniform_layout(rng: random.Random, specs: Sequence[Spec], ids: Sequence[str]) -> list[ShelfObject] | None:
    """The target (`specs[0]`) at the back (x in [0.87, 0.91], |y| <= 0.1, as layout.free_scene puts it), then the
    other objects at uniform free spots (`place_uniform`), the widest first (a crowded shelf fills up with the small
    ones); in the order of `specs`, or None when one does not fit."""
    target = shelf_object(specs[0], ids[0], round(rng.uniform(0.87, 0.91), 3), round(rng.uniform(-0.1, 0.1), 3), 0.0)
    placed = [target]
    rest = range(1, len(specs))
    found: dict[int, ShelfObject] = {}
    for k in sorted(rest, key=lambda k: -max(specs[k].size[:2] + (2 * specs[k].radius,))):
        o = place_uniform(rng, specs[k], ids[k], placed)
        if o is None:
            return None
        found[k] = o
    return [target] + [found[k] for k in rest]


def entry(o: ShelfObject, spec: Spec, rng: random.Random, weighed: bool = True) -> dict[str, Any]:
    """The scenario entry of the placed object `o`: id, a weight uniform in [0.05, 0.95] (when `weighed`), its
    position, shape and yaw."""
    e: dict[str, Any] = {"id": o.id}
    if weighed:
        e["weight"] = round(rng.uniform(0.05, 0.95), 2)
    e["xy"] = [o.x, o.y]
    e.update(spec.entry())
    if spec.oriented:
        e["yaw"] = o.yaw
    return e


# ---------------------------------------------------------------------------------------------- stocked in columns
# A shelf stocked in columns: objects slid in from the front, one behind the other, in columns side by side, as a
# shop or pantry shelf is filled: the layout of the crowded scenes (world.py's crowd_20 and crowd_30). Drawn
# uniformly over the free part of the shelf (uniform_layout), twenty or thirty objects stand a few millimetres apart
# everywhere: the hand needs about 40 mm beside a bottle it grasps (two 66 mm bottles side by side leave each other
# no lane below a 0.10 m centre distance), and such layouts leave the target no sequence (docs/bench/demo.md).
#
# The draw, from the seed's random stream:
# - the number of columns: the fewest whose depth (ROOM, the shelf's) holds the objects with their mean gaps, plus
#   `spare`; the objects go into them the target first, then the deepest first (a stocker evens the columns out),
#   each into a column drawn among those with room left, with a probability in proportion to the room it would
#   leave; then each column's order from the back is shuffled, the target staying at the back of its own;
# - boxes stand square to the shelf (yaw 0 or 90 degrees, +-3 degrees), a lying bottle along the column (+-6 degrees);
# - in a column, objects stand from the back panel, each DEPTH_GAP (drawn per object) in front of the one behind,
#   centred in the column within +-3 mm (as far as its width leaves); the target's column and the two beside it
#   (the hand reaching the target passes by them) are stocked only as deep as the arm reaches (layout.MAX_REACH,
#   NEAR_ROOM: the room counted for them), the other columns may stand beyond it, out of the hand's reach, as on a
#   real shelf;
# - a column is as wide as its widest object; two neighbouring columns stand packed or with an aisle a hand fits in
#   between them (COLUMN_GAPS, one of the two drawn per pair, then the gap in it); the whole is shifted by a uniform
#   draw among the offsets that keep it on the shelf with the target's column within TARGET_Y of the shelf's middle.
# A layout that does not fit (depth or width) is None: the seed is refused as "fit".

COLUMN_GAPS = ((GAP + 0.001, 0.015), (0.045, 0.07))  # m between two neighbouring columns: packed, or a hand's aisle
DEPTH_GAP = (GAP + 0.001, 0.02)  # m between two objects of a column
TARGET_Y = 0.1  # m: the target's column at most this far from the shelf's middle
X_BACK = SHELF["x_front"] + SHELF["depth"] - GAP  # m: the back panel, less GAP
X_FRONT = SHELF["x_front"] + GAP


def yaw_of(rng: random.Random, spec: Spec) -> float:
    """A box square to the shelf, a lying bottle along its column (module docstring); 0 for a standing cylinder."""
    if spec.shape == "box":
        return round(rng.choice((0.0, math.pi / 2)) + rng.uniform(-0.05, 0.05), 3)
    return round(rng.uniform(-0.1, 0.1), 3) if spec.lying else 0.0


def half_extent(spec: Spec, yaw: float) -> tuple[float, float]:
    """Half the footprint's extent along x and y at `yaw`."""
    fp = shelf_object(spec, "e", 0.0, 0.0, yaw).footprint()
    if not fp.corners:
        return fp.radius, fp.radius
    return max(abs(c[0]) for c in fp.corners), max(abs(c[1]) for c in fp.corners)


def _reach(y: float) -> float:
    """The largest x of an object's centre at `y` within the arm's reach (layout.MAX_REACH)."""
    return math.sqrt(max(MAX_REACH ** 2 - y ** 2, 0.0)) - 0.001


ROOM = X_BACK - X_FRONT  # m of depth a column holds
NEAR_ROOM = _reach(2 * TARGET_Y) - X_FRONT  # m of depth of the target's column and its neighbours (within reach)


def stocked(rng: random.Random, specs: Sequence[Spec], ids: Sequence[str], spare: int) -> list[ShelfObject] | None:
    """The objects `specs` (the first, the target) with `ids`, stocked in `spare` more columns than the fewest that
    hold them (module docstring), in the order of `specs`; None when the layout does not fit."""
    yaws = [yaw_of(rng, s) for s in specs]
    half = [half_extent(s, y) for s, y in zip(specs, yaws)]
    behind = [rng.uniform(*DEPTH_GAP) for _ in specs]  # m from the object behind it in its column
    need = math.ceil(sum(2 * h[0] + sum(DEPTH_GAP) / 2 for h in half) / ROOM)
    k = max(need, 1) + spare
    columns: list[list[int]] = [[] for _ in range(k)]
    depth = [0.0] * k  # m of depth taken, gaps included
    order = [0] + sorted(range(1, len(specs)), key=lambda i: -half[i][0])  # the target, then the deepest first
    room = [ROOM] * k
    for i in order:
        left = [room[c] - depth[c] - 2 * half[i][0] - (behind[i] if columns[c] else 0.0) for c in range(k)]
        if max(left) < 0.0:
            return None
        c = rng.choices(range(k), [max(v, 0.0) + 1e-9 * (v >= 0.0) for v in left])[0]
        depth[c] += 2 * half[i][0] + (behind[i] if columns[c] else 0.0)
        columns[c].append(i)
        if i == 0:  # the target's column and its neighbours: within reach
            room = [NEAR_ROOM if abs(j - c) <= 1 else ROOM for j in range(k)]
    near = [room[c] == NEAR_ROOM for c in range(k) if columns[c]]
    columns = [col[:1] + rng.sample(col[1:], len(col) - 1) if 0 in col else rng.sample(col, len(col))
               for col in columns if col]  # in a random order from the back, the target at the back of its own
    widths = [2 * max(half[i][1] for i in col) for col in columns]
    gaps = [rng.uniform(*rng.choice(COLUMN_GAPS)) for _ in columns[1:]]
    centres = [widths[0] / 2]
    for w0, w1, g in zip(widths, widths[1:], gaps):
        centres.append(centres[-1] + w0 / 2 + g + w1 / 2)
    mine = next(j for j, col in enumerate(columns) if 0 in col)
    edge = SHELF["width"] / 2 - GAP
    lo = max(-edge - (centres[0] - widths[0] / 2), -TARGET_Y - centres[mine])
    hi = min(edge - (centres[-1] + widths[-1] / 2), TARGET_Y - centres[mine])
    if lo > hi:
        return None
    shift = rng.uniform(lo, hi)
    placed: list[ShelfObject] = []
    at: dict[int, ShelfObject] = {}
    for col, centre, width, within in zip(columns, centres, widths, near):
        front = X_BACK
        for n, i in enumerate(col):
            slack = min(max(0.0, width / 2 - half[i][1]), 0.003)
            y = centre + shift + rng.uniform(-slack, slack)
            x = front - half[i][0] - (behind[i] if n else 0.0)
            x = min(x, _reach(y)) if within else x
            o = shelf_object(specs[i], ids[i], round(x, 3), round(y, 3), yaws[i])
            if not fits(o, placed, reach=within):
                return None
            placed.append(o)
            at[i] = o
            front = x - half[i][0]
    return [at[i] for i in range(len(specs))]
