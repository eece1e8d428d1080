"""What perception publishes of one object: `PerceivedObject`, with the fields of the scene's object model
(docs/perception.md, "Objects"; relocation_common's scene object), and its conversion at the pipeline's edge."""
from __future__ import annotations

import math
from dataclasses import dataclass

from relocation_common.scenario import Bottle

CYLINDER, BOX = "cylinder", "box"


@dataclass(frozen=True)
class PerceivedObject:
    """One object of a frame. x, y: the centre of its footprint on its support (base frame); z: the support's
    surface (the board it rests on); cylinder: radius, height = its length along its axis (vertical, or horizontal
    along `yaw` when `lying`); box: size (sx, sy, sz) in its own frame turned by `yaw` about the vertical, radius 0.
    listed: the scenario lists it (id, weight from there); else id u<k> and weight = volume x density
    (`weight_note`). conservative: no primitive fitted, the box bounds what was seen (never grasped). rgb: the mean
    colour measured (0..1, normalised by the marker's white); fit_rms: the fit's residual (m); pixel: where the
    debug image names it."""

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


def estimated_weight(volume: float, density: float) -> tuple[float, str]:
    """(weight in (0, 1], the note saying how): volume x density in kg, clipped to (0, 1] (phi_i, Eq. 8)."""
    raw = volume * density
    w = min(1.0, max(raw, 1e-3))
    note = f"estimated: {volume * 1000:.2f} L x {density:.0f} kg/m3 = {raw:.2f} kg"
    if w != raw:
        note += f", clipped to {w:g}"
    return w, note


def to_bottle(o: PerceivedObject) -> Bottle:
    """The scene's object model of today (an upright cylinder): the conversion the node publishes through until the
    object message carries shapes (relocation_common.ros_conversions); listed standing cylinders only."""
    return Bottle(o.id, o.label, o.rgb, o.weight, o.x, o.y, o.radius, o.height, o.is_target)
