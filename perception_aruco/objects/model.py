"""What perception publishes of one object: `PerceivedObject`, with the fields of the scene's object model
(docs/perception.md, "Objects"; relocation_common's scene object), and its conversion at the pipeline's edge."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from relocation_common.shelf_object import ShelfObject, estimated_weight

CYLINDER, BOX = "cylinder", "box"


@dataclass(frozen=True)
class PerceivedObject:
    """One object of a frame. x, y: the centre of its footprint on its support (base frame); z: the support's
    surface (the board it rests on); cylinder: radius, height = its length along its axis (vertical, or horizontal
    along `yaw` when `lying`); box: size (sx, sy, sz) in its own frame turned by `yaw` about the vertical, radius 0.
    listed: the scenario lists it (id, weight from there); else id u<k> and weight = volume x density
    (`weight_note`, config/perception.yaml's `unlisted_density`). conservative: no primitive fitted, the box bounds
    what was seen (never grasped). rgb: the mean colour measured (0..1, normalised by the marker's white); fit_rms:
    the fit's residual (m); pixel: where the debug image names it."""

    id: str
    label: str
    rgb: tuple[float, float, float]
    weight: float
    weight_note: str
    is_target: bool
    listed: bool
    shape: str
    x: float
    y: float
    z: float
    radius: float
    height: float
    size: tuple[float, float, float]
    yaw: float
    lying: bool
    conservative: bool
    fit_rms: float
    n_points: int
    pixel: tuple[int, int]

    @property
    def volume(self) -> float:
        """m^3 of the primitive."""
        if self.shape == CYLINDER:
            return math.pi * self.radius ** 2 * self.height
        return self.size[0] * self.size[1] * self.size[2]

    @property
    def top_z(self) -> float:
        """Highest point (m)."""
        return self.z + (2 * self.radius if self.shape == CYLINDER and self.lying else self.height)

    @property
    def reach(self) -> float:
        """Radius of the footprint's bounding circle (m): for overlap and track gates."""
        if self.shape == CYLINDER:
            return math.hypot(self.radius, self.height / 2) if self.lying else self.radius
        return math.hypot(self.size[0], self.size[1]) / 2

    @property
    def half_extent(self) -> tuple[float, float]:
        """Half the footprint's extent along the base frame's x and y (m): its axis-aligned bounding box."""
        if self.shape == CYLINDER and not self.lying:
            return self.radius, self.radius
        a, b = (self.height / 2, self.radius) if self.shape == CYLINDER else (self.size[0] / 2, self.size[1] / 2)
        c, s = abs(math.cos(self.yaw)), abs(math.sin(self.yaw))
        return c * a + s * b, s * a + c * b


def inside(o: PerceivedObject, points: np.ndarray, tol: float) -> np.ndarray:
    """Bool per point (N x 3, base frame): within the object's primitive grown by `tol`."""
    p = np.asarray(points, float) - (o.x, o.y, o.z)
    c, s = math.cos(o.yaw), math.sin(o.yaw)
    u, v, z = c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1], p[:, 2]   # in the object's frame
    if o.shape == CYLINDER and o.lying:   # axis along u, at the radius' height
        return (np.abs(u) <= o.height / 2 + tol) & (np.hypot(v, z - o.radius) <= o.radius + tol)
    in_z = (z >= -tol) & (z <= o.top_z - o.z + tol)
    if o.shape == CYLINDER:
        return in_z & (np.hypot(u, v) <= o.radius + tol)
    return in_z & (np.abs(u) <= o.size[0] / 2 + tol) & (np.abs(v) <= o.size[1] / 2 + tol)


def box_corners(o: PerceivedObject) -> np.ndarray:
    """8 x 3: the corners of a box holding the object (its footprint's bounding circle's square, support to top)."""
    r = o.reach
    return np.array([[o.x + dx, o.y + dy, z] for dx in (-r, r) for dy in (-r, r) for z in (o.z, o.top_z)])


def to_shelf_object(o: PerceivedObject) -> ShelfObject:
    """The scene's object model (relocation_common.shelf_object), which the object message carries
    (ros_conversions.objects_to_msg): the one conversion at the pipeline's edge."""
    return ShelfObject(o.id, o.label, o.rgb, o.weight, o.x, o.y, o.radius, o.height, o.is_target, o.shape, o.size,
                       o.yaw, o.lying, o.listed, o.weight_note, o.z, None, o.fit_rms, o.conservative)


def weight_estimate(o: PerceivedObject, density: float) -> tuple[float, str]:
    """(phi in (0, 1], the note saying how) of an object the scenario does not list: its volume x `density`
    (relocation_common.shelf_object.estimated_weight, the simulator's ground truth's too)."""
    return estimated_weight(to_shelf_object(o), density)
