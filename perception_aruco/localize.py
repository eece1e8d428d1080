"""Bottle axis position in the base frame from the segmented depth points (no rclpy).

A bottle is an upright cylinder of known radius r (from its colour class through the scenario). The camera sees
part of its side: points p_i (base frame) at horizontal distance r from the axis c = (x, y). The axis is the
least-squares solution of  min_c sum_i (|p_i,xy - c| - r)^2  (Gauss-Newton), started one radius behind the
visible surface along the horizontal viewing ray, with points farther than `inlier_tol` from the circle dropped
and the fit repeated (stray pixels of another class, specular highlights). The cap (top face) is excluded from
the fit: its points lie inside the circle. The base height z is the board the bottle stands on (top or bottom
shelf), decided by the points' heights.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from stpik_motion_planner.scenario import Bottle, Scenario

from .aruco import PerceptionError


class FitError(PerceptionError):
    """Too few or inconsistent points to place a bottle."""


@dataclass(frozen=True)
class LocalizeParams:
    min_pixels: int = 60          # fewer pixels of a class: the bottle counts as not visible (hidden)
    inlier_tol: float = 0.004     # m, |distance to axis - r| of an inlier
    cap_margin: float = 0.006     # m below the top of the bottle: points above are the cap, not the side
    min_inliers: int = 40
    iterations: int = 12


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
    if keep.sum() < params.min_inliers:
        raise FitError(f"only {int(keep.sum())} points within {params.inlier_tol * 1000:.0f} mm of the fitted circle")
    return centre, keep


def locate_bottle(bottle: Bottle, mask: np.ndarray, points: np.ndarray, scenario: Scenario,
                  camera_position: np.ndarray, params: LocalizeParams = LocalizeParams()) -> Detection:
    """Place one bottle from its class mask; FitError when it is not visible enough."""
    n = int(mask.sum())
    if n < params.min_pixels:
        raise FitError(f"{n} pixels of colour {bottle.label!r} (need {params.min_pixels})")
    # keep the largest connected blob's neighbourhood: stray pixels elsewhere (highlights) are dropped
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    r0, c0 = rows[0], cols[0]
    crop = mask[r0:rows[-1] + 1, c0:cols[-1] + 1].astype(np.uint8)
    _, comp, stats, _ = cv2.connectedComponentsWithStats(crop, connectivity=8)
    big = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    v, u = np.nonzero(comp == big)
    v, u = v + r0, u + c0
    p = points[v, u]
    s = scenario.shelf
    base = s.top_z if np.median(p[:, 2]) > s.top_z - s.board_thickness / 2 else s.bottom_z
    side = p[:, 2] < base + bottle.height - params.cap_margin
    if side.sum() < params.min_inliers:
        raise FitError(f"only the cap of {bottle.id!r} is visible")
    centre, keep = fit_axis(p[side, :2].astype(float), bottle.radius, camera_position, params)
    rms = float(np.sqrt(np.mean((np.linalg.norm(p[side][keep, :2] - centre, axis=1) - bottle.radius) ** 2)))
    return Detection(bottle.id, float(centre[0]), float(centre[1]), float(base), int(keep.sum()), rms,
                     (int(np.median(u)), int(np.median(v))))
