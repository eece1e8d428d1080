"""Which cluster is which object (docs/perception.md, "Objects", "Identity").

Listed objects (the scenario's) are matched to clusters as an assignment problem (scipy's linear_sum_assignment)
on the cost  colour + size + position:
- colour: the distance of the cluster's colour (normalised by the marker plate) to the object's colour shaded by
  the best gain (segmentation.colour_residuals), over `max_residual`; above 1: not that object;
- size: the largest difference of radius and half the height (cylinders, standing or lying) over `size_tol` (seen
  shorter is no difference when the top or a lying one's end may be hidden); above 1: not that object. A box:
  fitted as a box of its size, or showing one face only, that face one of its faces (box_face.py), its position
  then where the cluster puts the box. A
  cluster no free primitive fitted (a bottle mostly hidden) is that cylinder when a circle of its known radius fits
  its points (localize.locate_cylinder), unless its points lie on a straight line `flat_margin` times better than on
  that circle: a box's flat face, which no cylinder shows (a brown box's face taken by a black bottle 13 cm away);
- position: the distance to where the object is expected (its last perceived pose, its track; else the scenario's
  pose: objects start where it says) over `position_scale`, in full; from a track the arm came near since the object
  was last seen (`Memory.arm_near`: it may have carried or pushed it) at most 1, so an object moved while unseen is
  still that object. A track never jumps further than a cost of max_cost allows while the arm did not come near it
  (a cyan bottle taking a teal one's cluster 44 cm away during another object's relocation). It tells two objects of
  one colour apart.
A pair costing more than `max_cost` is no match. Clusters left are unlisted objects: one within `unlisted_gate` of
an unlisted object's last position keeps its id (assignment on the distance), the others get new ids u<k> in order
of first sight (tracking.SceneMemory).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from scipy.optimize import linear_sum_assignment

from relocation_common.scenario import PALETTE, TARGET_COLOR, TARGET_RGB, ShelfObject

from ..localize import FitError, LocalizeParams, locate_cylinder
from ..segmentation import SegmentationParams, colour_residuals
from .box_face import BoxPose, box_pose
from .clusters import Cluster
from .model import BOX, CYLINDER, PerceivedObject
from .params import ObjectParams
from .primitives import Primitive

NO_MATCH = 1e6
NOISE_FLOOR = 0.0005  # m: the least depth noise a fit's residual is compared with (localize.locate_cylinder's)
COLOURS = {**PALETTE, TARGET_COLOR: TARGET_RGB}


class Memory(Protocol):
    """What identity reads of the scene memory (tracking.SceneMemory)."""

    def expected(self, object_id: str) -> PerceivedObject | None:
        """The object's last perceived pose, or None."""

    def arm_near(self, object_id: str) -> bool:
        """Whether the arm came near the object's last perceived pose since it was seen there (it may have moved
        it)."""

    def held(self) -> dict[str, PerceivedObject]:
        """The listed objects still held at their last pose if not seen in this frame, by id."""

    def unlisted(self) -> dict[str, PerceivedObject]:
        """The unlisted objects ever seen, by id."""

    def new_ids(self, n: int) -> list[str]:
        """The ids of the next n new unlisted objects."""


@dataclass(frozen=True)
class Fitted:
    """A cluster with its primitive, its standing-cylinder circle points and its pixel (debug image)."""

    cluster: Cluster
    prim: Primitive
    circle_xy: np.ndarray
    pixel: tuple[int, int]


def colour_name(colour: np.ndarray, clipped: np.ndarray, seg: SegmentationParams) -> str:
    """The palette colour (or the target's green) nearest a cluster's colour, "" when none is within
    `max_residual`."""
    names = list(COLOURS)
    res = colour_residuals(colour[None, :], np.array([COLOURS[n] for n in names]) * 255.0, seg, clipped[None, :])[0]
    k = int(np.argmin(res))
    return names[k] if res[k] <= seg.max_residual else ""


def flat_face(xy: np.ndarray, centre: np.ndarray, radius: float, margin: float, noise: float) -> bool:
    """Whether points `xy` (a cluster's side points in x-y) lie on a straight line `margin` times better (rms) than
    on the circle of `radius` about `centre`: a box's face, not a cylinder's arc (whose bend over the visible chord,
    its sagitta, the line misses). Both rms over all the points; `noise` (the depth noise) bounds the line's from
    below, so a sliver too narrow to show its bend is no face."""
    d = xy - xy.mean(axis=0)
    line = float(np.linalg.svd(d, compute_uv=False)[-1]) / math.sqrt(len(xy))
    circle = float(np.sqrt(np.mean((np.linalg.norm(xy - centre, axis=1) - radius) ** 2)))
    return circle > margin * max(line, noise, NOISE_FLOOR)


def fit_bound(params: ObjectParams, loc: LocalizeParams) -> float:
    """The rms a primitive's fit may have in this frame (m): max(`fit_rms`, `fit_noise` x the depth noise)."""
    return max(params.fit_rms, params.fit_noise * loc.depth_noise)


def listed_box(b: ShelfObject, f: Fitted, camera: np.ndarray, params: ObjectParams,
               loc: LocalizeParams) -> BoxPose | None:
    """Listed box b's pose and size cost as cluster f shows it (box_face.box_pose: fitted as a box of its size, or
    by the one face it shows), None when f cannot be b."""
    return box_pose(b, f.prim, f.cluster.points, f.cluster.support, camera, params, fit_bound(params, loc))


def _size_cost(b: ShelfObject, f: Fitted, camera: np.ndarray, loc: LocalizeParams, tol: float,
               flat_margin: float) -> float:
    """Size cost of listed cylinder b for cluster f (module docstring); NO_MATCH when it cannot be b."""
    p = f.prim
    # seen shorter than it is: a lying one's end, a standing one's top may be hidden by what is nearer
    short = p.lying or not p.top_seen
    dh = max(p.height - b.height, 0.0 if short else b.height - p.height) / 2
    if p.shape == CYLINDER and not p.conservative and (not p.lying or abs(p.radius - b.radius) <= tol):
        return max(abs(p.radius - b.radius), dh) / tol   # a standing cylinder of another radius is another object
    try:  # a sliver, whose free fit is no cylinder of its radius (a box, lying, none): one of the known radius?
        centre = locate_cylinder(f.circle_xy, b.radius, camera, loc, b.id)[0]
    except FitError:
        return NO_MATCH
    if flat_face(f.circle_xy, centre, b.radius, flat_margin, loc.depth_noise):  # a box's face: no cylinder's
        return NO_MATCH
    # ... holding the whole cluster (a circle of a small radius also fits part of a wide jar's arc)
    spread = float(np.percentile(np.linalg.norm(f.cluster.points[:, :2] - centre, axis=1), 95))
    return dh / tol if spread <= b.radius + tol else NO_MATCH


def listed_costs(fitted: list[Fitted], objects: tuple[ShelfObject, ...], memory: Memory, seg: SegmentationParams,
                 params: ObjectParams, loc: LocalizeParams, camera: np.ndarray) -> np.ndarray:
    """L x M cost of listed object l being cluster m (module docstring); NO_MATCH where it cannot be."""
    cost = np.full((len(objects), len(fitted)), NO_MATCH)
    if not fitted or not objects:
        return cost
    colours = np.array([f.cluster.colour for f in fitted])
    clipped = np.array([f.cluster.clipped for f in fitted])
    # a cluster's median colour is its lit side's (the shading gain 0.75-1.2 measured on the shipped scenes): a
    # narrower gain range than a single pixel's tells olive from a shaded yellow
    shade = replace(seg, gain_min=params.cluster_gain_min, gain_max=params.cluster_gain_max)
    col = colour_residuals(colours, np.array([b.rgb for b in objects]) * 255.0, shade, clipped).T / seg.max_residual
    for j, b in enumerate(objects):
        was = memory.expected(b.id)
        ex, ey, ez = (was.x, was.y, was.z) if was is not None else (b.x, b.y, None)
        for m, f in enumerate(fitted):
            if col[j, m] > 1:
                continue
            x, y = f.prim.x, f.prim.y
            if b.shape == BOX:   # where the cluster puts the box (fitted, or behind the one face it shows)
                pose = listed_box(b, f, camera, params, loc)
                size, x, y = (NO_MATCH, x, y) if pose is None else (pose.size_cost, pose.x, pose.y)
            else:
                size = _size_cost(b, f, camera, loc, params.size_tol, params.flat_margin)
            if size > 1:
                continue
            dz = 0.0 if ez is None else f.cluster.support - ez
            d = math.sqrt((x - ex) ** 2 + (y - ey) ** 2 + dz ** 2) / params.position_scale
            # in full: objects start where the scenario says and stay where last seen (two of one colour told apart
            # by it); from a track the arm came near at most 1: an object it moved while unseen is still that object
            near = was is not None and memory.arm_near(b.id)
            cost[j, m] = col[j, m] + size + (min(d, 1.0) if near else d)
    return cost


def assign(cost: np.ndarray, max_cost: float) -> list[tuple[int, int]]:
    """(row, column) pairs of the least-cost assignment whose cost is at most max_cost."""
    if not cost.size:
        return []
    rows, cols = linear_sum_assignment(cost)
    return [(int(r), int(c)) for r, c in zip(rows, cols) if cost[r, c] <= max_cost]


def unlisted_ids(found: list[PerceivedObject], memory: Memory, gate: float) -> list[str]:
    """Ids of unlisted objects (in `found` order): the id of the unlisted object last seen within `gate` (on the
    same board), assigned on the distance; new ids u<k> for the others, in `found` order."""
    known = list(memory.unlisted().items())
    cost = np.full((len(found), len(known)), NO_MATCH)
    for a, o in enumerate(found):
        for k, (_, p) in enumerate(known):
            d = math.hypot(o.x - p.x, o.y - p.y)
            if d <= gate and abs(o.z - p.z) < 0.05:
                cost[a, k] = d
    ids: list[str | None] = [None] * len(found)
    for a, k in assign(cost, gate):
        ids[a] = known[k][0]
    new = iter(memory.new_ids(sum(i is None for i in ids)))
    return [i if i is not None else next(new) for i in ids]
