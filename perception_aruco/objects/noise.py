"""The depth noise at a cluster's depth (docs/perception.md, "Objects"): a depth camera's noise grows as the depth
squared (a stereo camera's error is z^2 / (focal length x baseline)), sigma(z) = sigma_1m * z^2, with sigma_1m
measured on the shelf's planes at their depths (shelf.ShelfFit.noise_1m). A cluster farther than the planes is
noisier than they are: its top face's points spread farther below its top (`cap_below`) and its top, their 99.5th
height percentile, lies farther above the face (`top_face`). The fit bound stays the noise measured on the planes
(`shelf`): scaled to the cluster's depth it let wrong fits of far slivers and unions through (docs/bench/perception.md,
"A standing cylinder's circle clear of its top face")."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DepthNoise:
    """sigma(z) = sigma_1m * z^2 of one frame (z: a point's depth along the camera's optical axis) and the noise
    measured on the shelf's planes (the fit bound's, primitives.fit_primitive)."""

    shelf: float          # m: the noise at the shelf's planes (shelf.ShelfFit.noise)
    sigma_1m: float       # m: the noise at 1 m of depth
    camera: np.ndarray    # (3,): the camera's position (base frame)
    axis: np.ndarray      # (3,): its optical axis (base frame, unit)

    def at(self, points: np.ndarray) -> float:
        """The rms of the noise over points (N x 3, base frame): sigma_1m x sqrt(mean(z^4)) (m)."""
        z = (points - self.camera) @ self.axis
        return float(self.sigma_1m * np.sqrt(np.mean(z ** 4))) if len(points) else 0.0


CAP_SIGMAS = 5.2  # the cap band's width in noise sigmas beyond the cap margin: the top (the points' 99.5th height
#                   percentile) lies 2.6 sigma above the top face, and 1 % of the face's points 2.6 sigma below it


def cap_below(top: float, margin: float, sigma: float) -> float:
    """The height above which a standing object's points may be its top face (m): `margin` (the band without noise)
    and CAP_SIGMAS depth noise sigmas (at the object's depth), two independent widths added in quadrature, below its
    top. Left in the side points, a cap's points lie inside the circle and pull its fitted radius down (a 90 mm jar
    1 m away: to 34 mm)."""
    return top - math.hypot(margin, CAP_SIGMAS * sigma)


def top_face(top: float, sigma: float) -> float:
    """The top face's height (m) from `top`, the points' 99.5th height percentile: under depth noise sigma (at the
    object's depth) that percentile of a face's points lies 2.58 sigma above the face (a cap's points' distances
    to `top` would all hold that offset)."""
    return top - 2.58 * sigma
