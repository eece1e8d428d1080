"""Bottle axis position in the base frame from the segmented depth points (no rclpy).

A bottle is an upright cylinder of known radius r (from its colour class through the scenario). The camera sees
part of its side: points p_i (base frame) at horizontal distance r from the axis c = (x, y). The axis is the
least-squares solution of  min_c sum_i (|p_i,xy - c| - r)^2  (Gauss-Newton), started one radius behind the
visible surface along the horizontal viewing ray, with points farther than `inlier_tol` from the circle dropped
and the fit repeated (stray pixels of another class, specular highlights). The cap (top face) is excluded from
the fit (its points lie inside the circle) except its rim: blob boundary pixels on the cap that are not occlusion
edges lie on the circle too, which places a bottle of which only the top is visible (behind others or the arm).
The base height z is the board the bottle stands on (top or bottom shelf), decided by the points' heights.
Checks (docs/perception.md, "Consistency checks"): the fit's rms residual must stay within `max_rms` and its axis
uncertainty within `max_uncertainty`; a second bottle-like blob of the same colour away from the fitted bottle is
returned (`Detection.elsewhere`) for the frame's identity check.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from relocation_common.scenario import Scenario, ShelfObject

from .aruco import PerceptionError


class FitError(PerceptionError):
    """Too few or inconsistent points to place a bottle."""


@dataclass(frozen=True)
class LocalizeParams:
    """Bounds of the axis fit (module docstring)."""

    min_pixels: int = 40          # fewer pixels of a class: the bottle counts as not visible (hidden)
    inlier_tol: float = 0.004     # m, |distance to axis - r| of an inlier
    cap_margin: float = 0.006     # m below the top of the bottle: points above are the cap, not the side
    min_inliers: int = 25
    min_inlier_fraction: float = 0.6  # of the side and rim points: less is not a cylinder of this radius
    above_top: float = 0.01       # m: pixels of a colour this far above its bottle's top are not that bottle
    occluder_gap: float = 0.01    # m: a neighbour this much nearer to the camera makes a blob edge an occlusion edge
    iterations: int = 12
    max_rms: float = 0.003        # m: rms distance of the inliers to the fitted circle
    elsewhere: float = 0.02       # m: a second blob of the colour this far outside the bottle is another object
    max_uncertainty: float = 0.0045  # m: 3 sigma of the fitted axis (from the fit's covariance) must stay below
    depth_noise: float = 0.0      # m: the frame's depth noise (set per frame from the shelf fit); floor of the sigma


@dataclass(frozen=True)
class Detection:
    """A located bottle: axis (x, y) and base height z in the base frame; n_points used; rms residual (m)."""

    id: str
    x: float
    y: float
    z: float
    n_points: int
    rms: float
    pixel: tuple[int, int]        # image point of the fit's visible centre (for the debug image)
    elsewhere: tuple[float, float] | None = None  # axis of a second bottle-like blob of this colour (identity check)


def fit_axis(xy: np.ndarray, radius: float, view_from: np.ndarray, params: LocalizeParams = LocalizeParams()):
    """(centre (2,), inlier mask) of a circle of known radius through N x 2 points; FitError when it fails."""
    if len(xy) < params.min_inliers:
        raise FitError(f"{len(xy)} points, need {params.min_inliers}")
    keep = np.ones(len(xy), bool)
    centre = None
    for _ in range(3):
        pts = xy[keep]
        if len(pts) < params.min_inliers:
            raise FitError(f"only {len(pts)} points within {params.inlier_tol * 1000:.0f} mm of a circle")
        if centre is None:
            mean = np.median(pts, axis=0)
            ray = mean - view_from[:2]
            centre = mean + radius * ray / np.linalg.norm(ray)
        for _ in range(params.iterations):
            d = pts - centre
            dist = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
            res = dist - radius
            jac = -d / dist[:, None]
            step = np.linalg.lstsq(jac, -res, rcond=None)[0]
            centre = centre + step
            if np.linalg.norm(step) < 1e-6:
                break
        new_keep = np.abs(np.linalg.norm(xy - centre, axis=1) - radius) < params.inlier_tol
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    if keep.sum() < max(params.min_inliers, params.min_inlier_fraction * len(xy)):
        raise FitError(f"only {int(keep.sum())} of {len(xy)} points within {params.inlier_tol * 1000:.0f} mm of the "
                       "fitted circle")
    return centre, keep


def locate_bottle(bottle: ShelfObject, mask: np.ndarray, points: np.ndarray, scenario: Scenario,
                  camera_position: np.ndarray, params: LocalizeParams = LocalizeParams(),
                  offset: tuple[int, int] = (0, 0)) -> Detection:
    """Place one bottle from its class mask; FitError when it is not visible enough. `offset`: (row, column) of
    mask[0, 0] in the image, when mask and points are a crop of it."""
    n = int(mask.sum())
    if n < params.min_pixels:
        raise FitError(f"{n} pixels of colour {bottle.label!r} (need {params.min_pixels})")
    # nothing of a bottle lies above its top: drop such pixels of its colour (e.g. the dark arm for 'black')
    s = scenario.shelf
    z = points[..., 2]
    with np.errstate(invalid="ignore"):
        mask = mask & (z < np.where(z > s.top_z - s.board_thickness / 2, s.top_z, s.bottom_z) + bottle.height
                       + params.above_top)
    if mask.sum() < params.min_pixels:
        raise FitError(f"{int(mask.sum())} pixels of colour {bottle.label!r} (need {params.min_pixels})")
    # keep the largest connected blob's neighbourhood: stray pixels elsewhere (highlights) are dropped
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    r0, r1, c0, c1 = max(rows[0] - 3, 0), rows[-1] + 4, max(cols[0] - 3, 0), cols[-1] + 4
    crop = mask[r0:r1, c0:c1].astype(np.uint8)
    _, comp, stats, _ = cv2.connectedComponentsWithStats(crop, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    order = np.argsort(areas)[::-1]
    big = (comp == 1 + int(order[0])).astype(np.uint8)
    other = (comp == 1 + int(order[1])) if len(order) > 1 and areas[order[1]] >= params.min_pixels else None
    v, u = np.nonzero(big)
    pts = points[r0:r1, c0:c1]
    p = pts[v, u]
    base = s.top_z if np.median(p[:, 2]) > s.top_z - s.board_thickness / 2 else s.bottom_z
    top = base + bottle.height - params.cap_margin
    side = p[:, 2] < top
    # rim of the cap: blob boundary pixels on the cap that are not an occlusion edge (nothing nearer next to them)
    dist = np.linalg.norm(pts - camera_position.astype(np.float32), axis=2)
    dist = np.where(np.isfinite(dist), dist, np.inf).astype(np.float32)
    nearest = cv2.erode(dist, np.ones((5, 5), np.uint8))  # min over a 5x5 neighbourhood
    rim = (big > 0) & (cv2.erode(big, np.ones((3, 3), np.uint8)) == 0) & (nearest > dist - params.occluder_gap)
    rim &= pts[..., 2] >= top
    # a real sensor's flying pixels: depth off its 3x3 median by more than occluder_gap (not on either surface)
    med = cv2.medianBlur(np.where(np.isfinite(dist), dist, 0).astype(np.float32), 3)
    steady = np.abs(dist - med) < params.occluder_gap
    side &= steady[v, u]
    rim &= steady
    use = np.concatenate([p[side, :2], pts[rim][:, :2]]).astype(float)
    if len(use) < params.min_inliers:
        raise FitError(f"too little of {bottle.id!r} visible: {int(side.sum())} side and {int(rim.sum())} rim "
                       f"points (need {params.min_inliers})")
    v, u = v + r0, u + c0
    centre, keep = fit_axis(use, bottle.radius, camera_position, params)
    rms = float(np.sqrt(np.mean((np.linalg.norm(use[keep] - centre, axis=1) - bottle.radius) ** 2)))
    if rms > params.max_rms:
        raise FitError(f"{bottle.id!r}: fit residual {rms * 1000:.1f} mm rms (bound {params.max_rms * 1000:.1f} mm)")
    d = use[keep] - centre
    jac = d / np.maximum(np.linalg.norm(d, axis=1), 1e-9)[:, None]
    cov = np.linalg.inv(jac.T @ jac + 1e-12 * np.eye(2))       # axis covariance / sigma^2 (Gauss-Newton)
    sd = max(rms, params.depth_noise, 0.0005) * math.sqrt(float(np.max(np.linalg.eigvalsh(cov))))
    if 3 * sd > params.max_uncertainty:
        raise FitError(f"too little of {bottle.id!r} visible to place it: axis uncertain by {3 * sd * 1000:.0f} mm "
                       "(3 sigma)")
    elsewhere = None if other is None else _another_bottle(pts[other], bottle, centre, camera_position, params)
    return Detection(bottle.id, float(centre[0]), float(centre[1]), float(base), int(keep.sum()), rms,
                     (int(np.median(u)) + offset[1], int(np.median(v)) + offset[0]),
                     None if elsewhere is None else (float(elsewhere[0]), float(elsewhere[1])))


def _another_bottle(q: np.ndarray, bottle: ShelfObject, centre: np.ndarray, camera_position: np.ndarray,
                    params: LocalizeParams) -> np.ndarray | None:
    """The axis of a second blob of the bottle's colour when it lies away from the fitted bottle and its points fit
    a circle of the bottle's radius too (another bottle-like object of this colour), else None."""
    q = q[np.isfinite(q).all(axis=1)][:, :2].astype(float)
    if len(q) < params.min_inliers or np.median(np.linalg.norm(q - centre, axis=1)) <= bottle.radius + \
            params.elsewhere:
        return None
    try:
        return fit_axis(q, bottle.radius, camera_position, params)[0]
    except FitError:
        return None
