"""Where a listed box is, given a cluster (docs/perception.md, "Identity": a listed box).

Two ways, in this order:
- fitted as a box (primitives.box: the top face shows the footprint): its size cost is half the differences of
  its footprint's shorter and longer sides and of its height over `size_tol`; the box at the fitted pose, its sides
  lined up with the listed ones (`box_yaw`);
- seen by one face only (no box of its size fitted: the top hidden under the ceiling board, or the top's grazing
  points and the flying pixels at its edge too noisy for the box fit, or the face and a sliver of its side fitted as a
  thin box): the points of the cluster's lower half lie on a straight line in x-y within the fit bound (max(`fit_rms`,
  `fit_noise` x the depth noise), the rms over the `TRIM` of them nearest it; an arc of a bottle does not); the face's
  extent along that line and its height fit one of the box's vertical faces (the extent's whole difference over
  `size_tol`: a face partly hidden is none, as a long face half hidden would pass for a short one; the whole faces
  measured 0.3-1.8 mm short on the generated cases; half the height's, seen shorter no difference when the top may be
  hidden); the box is then that face's owner: the face on its near side, its centre half the other side behind the
  face (away from the camera), and all but `absorb_outside` of the cluster's points within `size_tol` of it. The
  position cost is then the listed identity's (identity.listed_costs), at this pose.
A listed cylinder never takes such a cluster (identity.flat_face: a flat face is no cylinder's arc).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from relocation_common.shelf_object import ShelfObject, half_turn

from .model import BOX
from .params import ObjectParams
from .primitives import Primitive

MIN_FACE_POINTS = 20  # side points a face's line is fitted to
TRIM = 0.9  # the face's line rms over this fraction of its points nearest it (the realistic camera's flying pixels at
            # its vertical edges lie along the rays, off the face)


@dataclass(frozen=True)
class BoxPose:
    """A listed box's pose as a cluster shows it and the size cost of that; how: "fitted" or "face"."""

    x: float
    y: float
    yaw: float
    size_cost: float
    how: str


def box_yaw(p: Primitive, size: tuple[float, float, float]) -> float:
    """The yaw of fitted box p that lines its sides up with `size` (p's turned a quarter when its sides come in
    the other order), in (-pi/2, pi/2]."""
    swapped = (p.size[0] < p.size[1]) != (size[0] < size[1])
    return half_turn(p.yaw + (math.pi / 2 if swapped else 0.0))


def _height_cost(b: ShelfObject, p: Primitive) -> float:
    """Half the height difference (m); seen shorter counts nothing when the top (a lying one's end) may be hidden."""
    short = p.lying or not p.top_seen
    return max(p.height - b.height, 0.0 if short else b.height - p.height) / 2


def on_face(b: ShelfObject, p: Primitive, points: np.ndarray, support: float, camera: np.ndarray,
            params: ObjectParams, bound: float) -> BoxPose | None:
    """Box b owning the one face the cluster `points` shows (module docstring), or None."""
    top = float(np.percentile(points[:, 2], 99.5))
    side = points[points[:, 2] < (support + top) / 2, :2]   # the face's lower half: no top face, no top edge
    if len(side) < MIN_FACE_POINTS:
        return None
    mean = side.mean(axis=0)
    u = np.linalg.eigh(np.cov((side - mean).T))[1][:, 1]   # the face's direction in x-y
    n = np.array([-u[1], u[0]])
    off = np.sort(np.abs((side - mean) @ n))[:max(1, int(TRIM * len(side)))]
    if float(np.sqrt(np.mean(off ** 2))) > bound:
        return None   # not one flat face
    if float(n @ (mean - camera[:2])) < 0:
        n = -n   # away from the camera: where the box's body is
    t = (points[:, :2] - mean) @ u
    lo, hi = (float(v) for v in np.percentile(t, [0.5, 99.5]))
    dh = _height_cost(b, p)
    k = min((0, 1), key=lambda i: abs(hi - lo - b.size[i]))   # the box's side the face is
    cost = max(abs(hi - lo - b.size[k]), dh) / params.size_tol   # the whole difference: a face partly hidden is none
    if cost > 1:
        return None
    centre = mean + u * (lo + hi) / 2 + n * b.size[1 - k] / 2
    yaw = math.atan2(u[1], u[0]) + (0.0 if k == 0 else math.pi / 2)   # the box's x side along the face when k = 0
    c, s = math.cos(yaw), math.sin(yaw)
    d = points[:, :2] - centre
    loc_u, loc_v = d @ np.array([c, s]), d @ np.array([-s, c])
    tol = params.size_tol
    held = (np.abs(loc_u) <= b.size[0] / 2 + tol) & (np.abs(loc_v) <= b.size[1] / 2 + tol) & \
        (points[:, 2] <= support + b.height + tol)
    if float(np.mean(held)) < 1.0 - params.absorb_outside:
        return None
    return BoxPose(float(centre[0]), float(centre[1]), half_turn(yaw), cost, "face")


def box_pose(b: ShelfObject, p: Primitive, points: np.ndarray, support: float, camera: np.ndarray,
             params: ObjectParams, bound: float) -> BoxPose | None:
    """Listed box b's pose and size cost from a cluster (its primitive p, its points): fitted as a box of its size,
    else by the one face it shows (module docstring); None when neither."""
    if p.shape == BOX and not p.conservative:
        sides = np.abs(np.sort(p.size[:2]) - np.sort(b.size[:2])) / 2
        cost = max(float(sides.max()), _height_cost(b, p)) / params.size_tol
        if cost <= 1:
            return BoxPose(p.x, p.y, box_yaw(p, b.size), cost, "fitted")
    return on_face(b, p, points, support, camera, params, bound)
