"""A standing cylinder's axis from the depth points of its cluster (no rclpy).

The camera sees part of the cylinder's side: points p_i (base frame) at horizontal distance r from the axis
c = (x, y). The axis is the least-squares solution of  min_c sum_i (|p_i,xy - c| - r)^2  (Gauss-Newton), started
one radius behind the visible surface along the horizontal viewing ray, with points farther than `inlier_tol` from
the circle dropped and the fit repeated. `fit_axis` fits a circle of known radius (a listed object's, from the
scenario), `fit_circle` one whose radius is fitted too, within bounds (an object the scenario does not describe).
The cap (top face) is excluded from the fit (its points lie inside the circle) except its rim: the silhouette's
outline pixels on the cap that are not occlusion edges lie on the circle too, which places a cylinder of which only the
top is visible (`circle_points`). Checks (docs/perception.md, "Consistency checks"): the known-radius fit's rms
residual must stay within `max_rms` and its axis uncertainty within `max_uncertainty` (`locate_cylinder`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from .aruco import PerceptionError
from .objects.params import value


class FitError(PerceptionError):
    """Too few or inconsistent points to place an object."""


@dataclass(frozen=True)
class LocalizeParams:
    """Bounds of the axis fit (module docstring)."""

    min_pixels: int = field(default_factory=value("min_pixels"))  # fewer points: not visible enough to place
    inlier_tol: float = field(default_factory=value("inlier_tol"))  # m, |distance to axis - r| of an inlier
    cap_margin: float = 0.006     # m below the top of the cylinder: points above are the cap, not the side
    min_inliers: int = 25
    min_inlier_fraction: float = 0.6  # of the side and rim points: less is not a cylinder of this radius
    occluder_gap: float = 0.01    # m: a neighbour this much nearer to the camera makes a blob edge an occlusion edge
    iterations: int = 12
    max_rms: float = 0.003        # m: rms distance of the inliers to the fitted circle
    max_uncertainty: float = 0.0045  # m: 3 sigma of the fitted axis (from the fit's covariance) must stay below
    depth_noise: float = 0.0      # m: the frame's depth noise (set per frame from the shelf fit); floor of the sigma


def _gauss_newton(pts: np.ndarray, centre: np.ndarray, radius: float | None, iterations: int) -> tuple[np.ndarray,
                                                                                                       float]:
    """Least-squares circle through pts: (centre, radius); radius None: fitted too."""
    r = 0.0 if radius is None else radius
    x = np.r_[centre, r] if radius is None else centre.copy()
    px, py = pts[:, 0], pts[:, 1]
    jac = np.empty((len(pts), 2 if radius is not None else 3))
    if radius is None:
        jac[:, 2] = -1.0
    for _ in range(iterations):
        dx, dy = px - x[0], py - x[1]
        dist = np.maximum(np.sqrt(dx * dx + dy * dy), 1e-9)   # np.linalg.norm's arithmetic, without its overhead
        res = dist - (x[2] if radius is None else r)
        np.divide(-dx, dist, out=jac[:, 0])
        np.divide(-dy, dist, out=jac[:, 1])
        try:  # the normal equations (2 or 3 unknowns): as lstsq, a fraction of its cost
            step = np.linalg.solve(jac.T @ jac, -jac.T @ res)
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(jac, -res, rcond=None)[0]
        x = x + step
        if math.sqrt(float(step @ step)) < 1e-7:   # np.linalg.norm(step)
            break
    return x[:2], float(x[2]) if radius is None else r


def algebraic_circle(xy: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Kasa's algebraic circle fit (linear least squares of x^2 + y^2 = 2 a x + 2 b y + c): the start of the
    geometric fit; None when degenerate (points on a line)."""
    a = np.c_[2 * xy, np.ones(len(xy))]
    sol, *_ = np.linalg.lstsq(a, np.sum(xy ** 2, axis=1), rcond=None)
    r2 = float(sol[2] + sol[0] ** 2 + sol[1] ** 2)
    return (sol[:2], math.sqrt(r2)) if r2 > 0 and np.isfinite(r2) else None


def _trimmed(xy: np.ndarray, view_from: np.ndarray, r0: float, radius: float | None, tol: float, min_inliers: int,
             iterations: int, start: np.ndarray | None = None) -> tuple[np.ndarray, float, np.ndarray]:
    """Fit, drop points off the circle by more than tol, refit (3 rounds): (centre, radius, inlier mask)."""
    keep = np.ones(len(xy), bool)
    centre: np.ndarray | None = start
    r = r0
    for _ in range(3):
        pts = xy[keep]
        if len(pts) < min_inliers:
            raise FitError(f"only {len(pts)} points within {tol * 1000:.0f} mm of a circle")
        if centre is None:
            mean = np.median(pts, axis=0)
            ray = mean - view_from[:2]
            centre = mean + r0 * ray / max(float(np.linalg.norm(ray)), 1e-9)
        centre, r = _gauss_newton(pts, centre, radius, iterations)
        new_keep = np.abs(np.linalg.norm(xy - centre, axis=1) - r) < tol
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    assert centre is not None
    return centre, r, keep


def fit_axis(xy: np.ndarray, radius: float, view_from: np.ndarray,
             params: LocalizeParams = LocalizeParams()) -> tuple[np.ndarray, np.ndarray]:
    """(centre (2,), inlier mask) of a circle of known radius through N x 2 points; FitError when it fails."""
    if len(xy) < params.min_inliers:
        raise FitError(f"{len(xy)} points, need {params.min_inliers}")
    centre, _, keep = _trimmed(xy, view_from, radius, radius, params.inlier_tol, params.min_inliers,
                               params.iterations)
    if keep.sum() < max(params.min_inliers, params.min_inlier_fraction * len(xy)):
        raise FitError(f"only {int(keep.sum())} of {len(xy)} points within {params.inlier_tol * 1000:.0f} mm of the "
                       "fitted circle")
    return centre, keep


def fit_circle(xy: np.ndarray, view_from: np.ndarray, bounds: tuple[float, float], tol: float,
               min_points: int = 12, start: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, float,
                                                                                              np.ndarray]:
    """(centre, radius, inlier mask) of a circle whose radius is fitted too, started at `start` (centre, radius) or
    the algebraic fit (or, when that is far out of bounds, at the middle of `bounds` one radius behind the points);
    FitError when it is out of bounds or most points are off it."""
    if len(xy) < min_points:
        raise FitError(f"{len(xy)} side and rim points, need {min_points}")
    kasa = start or algebraic_circle(xy)   # a start near the answer: from the middle of the bounds a short arc diverged
    if kasa is not None and bounds[0] / 2 <= kasa[1] <= 2 * bounds[1]:
        centre, r, keep = _trimmed(xy, view_from, kasa[1], None, tol, min_points, 20, kasa[0])
    else:
        centre, r, keep = _trimmed(xy, view_from, sum(bounds) / 2, None, tol, min_points, 20)
    if not bounds[0] <= r <= bounds[1]:
        raise FitError(f"radius {r * 1000:.0f} mm out of [{bounds[0] * 1000:.0f}, {bounds[1] * 1000:.0f}] mm")
    if keep.sum() < 0.6 * len(xy):
        raise FitError(f"only {int(keep.sum())} of {len(xy)} points within {tol * 1000:.0f} mm of the circle")
    return centre, r, keep


def circle_points(rows: np.ndarray, cols: np.ndarray, image_points: np.ndarray, top: float,
                  camera_position: np.ndarray, params: LocalizeParams, clear: float) -> tuple[np.ndarray, np.ndarray]:
    """(N x 2 (x, y) points of a standing cylinder's circle, N bool: the ones clear of its top face) of its side
    (below the cap: `cap_margin` under the top) and the cap's rim (the silhouette's outline on the cap where it is not
    an occlusion edge: nothing nearer next to it; a hole in the depth inside the cap makes no rim). rows, cols: the
    cluster's pixels; image_points: HxWx3 base-frame points of the frame; top: the cylinder's top (m); clear: the
    height below which a side point is clear of the top face under the depth noise (objects.noise.cap_below): the
    side points above it may be cap points, inside the circle (the rim is on it)."""
    h, w = image_points.shape[:2]
    r0, r1 = max(int(rows.min()) - 3, 0), min(int(rows.max()) + 4, h)
    c0, c1 = max(int(cols.min()) - 3, 0), min(int(cols.max()) + 4, w)
    mask = np.zeros((r1 - r0, c1 - c0), np.uint8)
    mask[rows - r0, cols - c0] = 1
    filled = np.zeros_like(mask)   # the silhouette, its holes filled: their edges are no rim
    cv2.drawContours(filled, cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0], -1, 1, cv2.FILLED)
    pts = image_points[r0:r1, c0:c1]
    own = pts[rows - r0, cols - c0]
    side = own[own[:, 2] < top - params.cap_margin]
    dist = np.linalg.norm(pts - camera_position.astype(np.float32), axis=2)
    dist = np.where(np.isfinite(dist), dist, np.inf).astype(np.float32)
    nearest = cv2.erode(dist, np.ones((5, 5), np.uint8))  # min over a 5x5 neighbourhood
    with np.errstate(invalid="ignore"):
        rim = (mask > 0) & (cv2.erode(filled, np.ones((3, 3), np.uint8)) == 0) & (nearest > dist - params.occluder_gap)
        rim &= pts[..., 2] >= top - params.cap_margin
    xy = np.concatenate([side[:, :2], pts[rim][:, :2]]).astype(float)
    return xy, np.r_[side[:, 2] < clear, np.ones(int(rim.sum()), bool)]


def locate_cylinder(xy: np.ndarray, radius: float, camera_position: np.ndarray, params: LocalizeParams,
                    name: str) -> tuple[np.ndarray, float, int]:
    """(axis (2,), rms, inliers) of a standing cylinder of known radius through its circle points; FitError when
    it is not visible enough or the fit is doubtful (rms, axis uncertainty: module docstring)."""
    if len(xy) < params.min_inliers:
        raise FitError(f"too little of {name!r} visible: {len(xy)} side and rim points (need {params.min_inliers})")
    centre, keep = fit_axis(xy, radius, camera_position, params)
    rms = float(np.sqrt(np.mean((np.linalg.norm(xy[keep] - centre, axis=1) - radius) ** 2)))
    if rms > params.max_rms:
        raise FitError(f"{name!r}: fit residual {rms * 1000:.1f} mm rms (bound {params.max_rms * 1000:.1f} mm)")
    d = xy[keep] - centre
    jac = d / np.maximum(np.linalg.norm(d, axis=1), 1e-9)[:, None]
    cov = np.linalg.inv(jac.T @ jac + 1e-12 * np.eye(2))       # axis covariance / sigma^2 (Gauss-Newton)
    sd = max(rms, params.depth_noise, 0.0005) * math.sqrt(float(np.max(np.linalg.eigvalsh(cov))))
    if 3 * sd > params.max_uncertainty:
        raise FitError(f"too little of {name!r} visible to place it: axis uncertain by {3 * sd * 1000:.0f} mm "
                       "(3 sigma)")
    return centre, rms, int(keep.sum())
