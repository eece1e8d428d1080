"""The object model: every object on the shelf, listed in the scenario or not, standing or lying, cylinder or box.

Frames: the robot base frame (x towards the shelf, z up, metres). An object's `x, y` is the centre of its footprint
on the board it rests on (`support_z`): a standing cylinder's base centre, a lying cylinder's or a box's centre
seen from above. Its pose in the ROS convention (shape_msgs/SolidPrimitive, as moveit_msgs/CollisionObject has it:
the primitive's centre, a cylinder's axis along its z) is `centre()` and `rotation()`; `at_pose` is the inverse,
the object placed at a measured centre and orientation (the simulator's ground truth, a perceived primitive).
A cylinder stands while its axis is within UPRIGHT_TILT of the vertical and lies beyond (`lying`; `tilt_of_quaternion`
and `support_height` read a bare pose as the closed loop's checks do). Footprints (`footprint`,
`Footprint.overlaps`) are what the scenario's overlap checks and the simulator's
disturbances compare: circles and convex polygons, separated along an axis (the separating axis theorem; numpy,
a few lines, where a polygon library would be a new dependency for three shapes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from . import geometry
from .config import ConfigError, node_section
from .geometry import rpy_matrix
from .paths import config_file

SHAPES = ("cylinder", "box")
UPRIGHT_TILT = math.radians(20)  # rad: a cylinder whose axis is tilted more from the vertical is not standing (lying)
EXACT_TILT = 1e-6  # rad: a cylinder within this of upright (or of flat, lying) is exactly so (`tilt` None)
DECIMALS = 9  # a measured pose's derived numbers are rounded to 1e-9 m / rad: an object survives a round trip
MIN_ESTIMATE = 0.01  # kg: an estimated weight is clipped to [MIN_ESTIMATE, 1] (phi must be in (0, 1], Eq. 8)


@dataclass(frozen=True)
class ShelfObject:
    """One object on the shelf (module docstring for the frames).

    A cylinder has `radius` and `height` (its length along its axis) and `size` (2r, 2r, h), set from them; a box
    has `size` (sx, sy, sz in its own frame, z vertical), `radius` 0 and `height` sz, set from it. `yaw`: the turn
    about the vertical of a box, of a lying cylinder's axis or of the direction a standing one leans to. `tilt`:
    a cylinder's axis from the vertical when measured neither exactly upright nor exactly flat (None: 0 standing,
    pi/2 lying). `listed`: in the scenario's `objects:`; an unlisted one (found by perception, or only in the
    simulator's world) has an estimated weight and says how in `weight_note`. `fit_rms`: perception's fit residual
    (m), 0 for ground truth; `conservative`: a cluster no primitive fits, as its bounding box (never grasped)."""

    id: str
    label: str
    rgb: tuple[float, float, float]
    weight: float
    x: float
    y: float
    radius: float
    height: float
    is_target: bool = False
    shape: str = "cylinder"
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    lying: bool = False
    listed: bool = True
    weight_note: str = ""
    support_z: float | None = None
    tilt: float | None = None
    fit_rms: float = 0.0
    conservative: bool = False

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"object {self.id!r}: shape must be one of {', '.join(SHAPES)}, got {self.shape!r}")
        if self.shape == "cylinder":
            object.__setattr__(self, "size", (2 * self.radius, 2 * self.radius, self.height))
        else:
            if self.lying:
                raise ValueError(f"object {self.id!r}: a box does not lie; give its size as it rests")
            sx, sy, sz = (float(v) for v in self.size)
            object.__setattr__(self, "size", (sx, sy, sz))
            object.__setattr__(self, "radius", 0.0)
            object.__setattr__(self, "height", sz)

    # ------------------------------------------------------------------------------------------ pose
    @property
    def axis_tilt(self) -> float:
        """Angle (rad) of the primitive's z axis from the vertical: `tilt`, or 0 standing, pi/2 lying."""
        if self.tilt is not None:
            return self.tilt
        return math.pi / 2 if self.lying else 0.0

    def rotation(self) -> np.ndarray:
        """The primitive's orientation (3x3): a cylinder's z axis along its axis, Rz(yaw) Ry(tilt); a box Rz(yaw)."""
        return rpy_matrix((0.0, self.axis_tilt if self.shape == "cylinder" else 0.0, self.yaw))

    def _support(self) -> float:
        if self.support_z is None:
            raise ValueError(f"object {self.id!r} has no support_z: the height of the board it rests on is unknown")
        return self.support_z

    @property
    def half_height(self) -> float:
        """Half the vertical extent of the primitive as it rests (its centre's height above its support)."""
        if self.shape == "box":
            return self.size[2] / 2
        t = self.axis_tilt
        return self.height / 2 * abs(math.cos(t)) + self.radius * math.sin(t)

    def centre(self) -> np.ndarray:
        """The primitive's centre (base frame): ObjectState.pose.position."""
        c = np.array([self.x, self.y, self._support() + self.half_height])
        if self.shape == "cylinder" and not self.lying:  # x, y is the base centre: the axis leans from there
            c[:2] += self.rotation()[:2, 2] * self.height / 2
        return c

    def base(self) -> np.ndarray:
        """The centre of a cylinder's base (its lower end face; a box's bottom face centre)."""
        return self.centre() - self.rotation()[:, 2] * self.height / 2

    @property
    def top_z(self) -> float:
        """Height of the object's highest point."""
        return self._support() + 2 * self.half_height

    @property
    def upright_radius(self) -> float:
        """Radius of the vertical cylinder about the object standing that holds it at any turn about the vertical:
        a cylinder's radius, a box's half-diagonal (a box in its slot stands turned as the hand held it)."""
        return math.hypot(self.size[0], self.size[1]) / 2 if self.shape == "box" else self.radius

    @property
    def volume(self) -> float:
        """m^3."""
        if self.shape == "box":
            return self.size[0] * self.size[1] * self.size[2]
        return math.pi * self.radius ** 2 * self.height

    # ------------------------------------------------------------------------------------------ footprint
    def footprint(self, margin: float = 0.0) -> "Footprint":
        """Its outline on the board, grown by `margin`: a standing cylinder's base circle; a lying cylinder's or a
        box's rectangle (a leaning cylinder's: its axis projected, plus the radius)."""
        if self.shape == "cylinder" and not self.lying:
            return Footprint((self.x, self.y), self.radius + margin, ())
        if self.shape == "box":
            half = (self.size[0] / 2 + margin, self.size[1] / 2 + margin)
        else:
            t = self.axis_tilt
            half = (self.height / 2 * math.sin(t) + self.radius * abs(math.cos(t)) + margin, self.radius + margin)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        corners = tuple((self.x + c * u - s * v, self.y + s * u + c * v)
                        for u, v in ((half[0], half[1]), (-half[0], half[1]), (-half[0], -half[1]),
                                     (half[0], -half[1])))
        return Footprint((self.x, self.y), 0.0, corners)

    def describe(self) -> str:
        """A short phrase for log lines: 'box 0.10 x 0.06 x 0.12 m', 'cylinder r 0.033 h 0.160 m, lying'."""
        if self.shape == "box":
            return "box {:.2f} x {:.2f} x {:.2f} m".format(*self.size)
        return f"cylinder r {self.radius:.3f} h {self.height:.3f} m" + (", lying" if self.lying else "")

    def key(self, top_z: float) -> str:
        """The object as the motion planner's per-question seeds hash it (planning.planner.question_rng): an upright
        listed cylinder resting on the top shelf (`top_z`) as its record read before the object model had shapes
        (the class was `Bottle`), so the questions of every shipped scene keep their seeds and the committed
        feasibility caches stay valid; any other field that differs from such a bottle's is appended."""
        legacy = (f"Bottle(id={self.id!r}, label={self.label!r}, rgb={self.rgb!r}, weight={self.weight!r}, "
                  f"x={self.x!r}, y={self.y!r}, radius={self.radius!r}, height={self.height!r}, "
                  f"is_target={self.is_target!r})")
        extra = [f"{k}={v!r}" for k, v, plain in (
            ("shape", self.shape, "cylinder"), ("size", self.size, self.size if self.shape == "cylinder" else None),
            ("yaw", self.yaw, 0.0), ("lying", self.lying, False), ("listed", self.listed, True),
            ("weight_note", self.weight_note, ""), ("support_z", self.support_z, self.support_z
                                                    if self.support_z in (None, top_z) else None),
            ("tilt", self.tilt, None), ("fit_rms", self.fit_rms, 0.0), ("conservative", self.conservative, False))
            if v != plain]
        return legacy + (f"+({', '.join(extra)})" if extra else "")


def objects_key(objects: Sequence[ShelfObject], top_z: float) -> str:
    """The objects as `repr` printed a tuple of them before they had shapes (ShelfObject.key)."""
    keys = [o.key(top_z) for o in objects]
    return "(" + ", ".join(keys) + ("," if len(keys) == 1 else "") + ")"


def half_turn(yaw: float) -> float:
    """A yaw in (-pi/2, pi/2] (unchanged when it is): a box and a flat lying cylinder are the same turned by pi."""
    if -math.pi / 2 < yaw <= math.pi / 2:
        return yaw + 0.0
    return -((math.pi / 2 - yaw) % math.pi - math.pi / 2) + 0.0  # + 0.0: never -0.0


def full_turn(yaw: float) -> float:
    """A yaw in [-pi, pi) (unchanged when it is)."""
    if -math.pi <= yaw < math.pi:
        return yaw + 0.0
    return (yaw + math.pi) % (2 * math.pi) - math.pi


def at_pose(o: ShelfObject, centre: ArrayLike, rot: ArrayLike) -> ShelfObject:
    """`o` (id, shape, size, ...) placed at a primitive's `centre` and orientation `rot` (3x3; shape_msgs'
    convention): a cylinder standing (axis within UPRIGHT_TILT of the vertical; x, y its base centre) or lying
    (x, y its centre), its tilt kept when it is neither exactly upright nor flat; a box resting on the face nearest
    to horizontal (its size reordered so that its z is the most vertical of its axes), yaw from its x axis. The
    support is the primitive's lowest point."""
    c, r = np.asarray(centre, float).reshape(3), np.asarray(rot, float).reshape(3, 3)
    if o.shape == "box":
        k = int(np.argmax(np.abs(r[2, :])))
        i, j = (k + 1) % 3, (k + 2) % 3
        size = (o.size[i], o.size[j], o.size[k])
        low = c[2] - sum(o.size[m] / 2 * abs(float(r[2, m])) for m in range(3))
        return replace(o, x=_r(c[0]), y=_r(c[1]), size=size, yaw=_r(half_turn(math.atan2(r[1, i], r[0, i]))),
                       lying=False, tilt=None, support_z=_r(low))
    a = r[:, 2] if r[2, 2] >= 0 else -r[:, 2]
    t = math.acos(min(1.0, float(a[2])))
    lying = t > UPRIGHT_TILT
    exact = abs(t - (math.pi / 2 if lying else 0.0)) < EXACT_TILT
    lean = math.atan2(a[1], a[0])
    yaw = (half_turn(lean) if lying else 0.0) if exact else full_turn(lean)
    low = c[2] - o.height / 2 * float(a[2]) - o.radius * math.sin(t)
    xy = c[:2] if lying else c[:2] - a[:2] * o.height / 2
    return replace(o, x=_r(xy[0]), y=_r(xy[1]), yaw=_r(yaw), lying=lying, tilt=None if exact else _r(t),
                   support_z=_r(low))


def _r(v: float) -> float:
    return round(float(v), DECIMALS)


# ---------------------------------------------------------------------------------------------- footprints
@dataclass(frozen=True)
class Footprint:
    """A 2-D outline: a circle (`radius` > 0 about `centre`, no corners) or a convex polygon (`corners`)."""

    centre: tuple[float, float]
    radius: float
    corners: tuple[tuple[float, float], ...]

    def _axes(self, other: "Footprint") -> list[np.ndarray]:
        """The candidate separating axes: the polygons' edge normals; for a circle, the direction to the nearest
        corner (or centre) of the other."""
        out = []
        for f, g in ((self, other), (other, self)):
            if f.corners:
                p = np.asarray(f.corners)
                e = np.roll(p, -1, axis=0) - p
                out += [np.array([-v[1], v[0]]) for v in e]
            else:
                pts = np.asarray(g.corners) if g.corners else np.asarray([g.centre])
                nearest = pts[np.argmin(np.linalg.norm(pts - f.centre, axis=1))]
                out.append(nearest - np.asarray(f.centre))
        return [v / n for v in out if (n := float(np.linalg.norm(v))) > 1e-12]

    def _project(self, axis: np.ndarray) -> tuple[float, float]:
        if self.corners:
            s = np.asarray(self.corners) @ axis
            return float(s.min()), float(s.max())
        c = float(np.asarray(self.centre) @ axis)
        return c - self.radius, c + self.radius

    def overlaps(self, other: "Footprint") -> bool:
        """True when the two outlines share area (touching is not overlapping)."""
        if not self.corners and not other.corners:
            return math.dist(self.centre, other.centre) < self.radius + other.radius
        for axis in self._axes(other) or [np.array([1.0, 0.0])]:
            a0, a1 = self._project(axis)
            b0, b1 = other._project(axis)
            if a1 <= b0 or b1 <= a0:
                return False
        return True

    def inside(self, x0: float, x1: float, y0: float, y1: float) -> bool:
        """True when the outline lies within the rectangle [x0, x1] x [y0, y1]."""
        if self.corners:
            p = np.asarray(self.corners)
            return bool(p[:, 0].min() >= x0 and p[:, 0].max() <= x1 and p[:, 1].min() >= y0 and p[:, 1].max() <= y1)
        (cx, cy), r = self.centre, self.radius
        return x0 + r <= cx <= x1 - r and y0 + r <= cy <= y1 - r


# ---------------------------------------------------------------------------------------------- weights
@lru_cache(maxsize=1)
def unlisted_density() -> float:
    """kg/m^3: the density an unlisted object's weight is estimated with (config/perception.yaml,
    `unlisted_density`: perception's estimate and the simulator's ground truth read this one value)."""
    v = node_section(config_file("perception.yaml"), "perception").get("unlisted_density")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise ConfigError(f"config/perception.yaml: unlisted_density must be a positive number (kg/m^3), got {v!r}")
    return float(v)


def estimated_weight(o: ShelfObject, density: float) -> tuple[float, str]:
    """(phi, note) of an object whose weight nobody gave: its volume x `density` (kg), clipped to
    [MIN_ESTIMATE, 1] (phi in (0, 1], Eq. 8); the note says how, e.g. "0.41 L x 600 kg/m3 = 0.25 kg"."""
    kg = o.volume * density
    w = min(1.0, max(MIN_ESTIMATE, kg))
    note = f"{o.volume * 1000:.2f} L x {density:.0f} kg/m3 = {kg:.2f} kg" + (f", clipped to {w:g}" if w != kg else "")
    return w, note


# ---------------------------------------------------------------------------------------------- bare poses
def tilt_of_quaternion(w: float, x: float, y: float, z: float) -> float:
    """Angle (rad) between a body's z axis and the vertical, from its orientation (w, x, y, z; a zero quaternion is
    upright)."""
    return geometry.tilt(geometry.wxyz_matrix((w, x, y, z)))


def support_height(base_z: float, radius: float, tilt: float) -> float:
    """Height of the surface a bottle rests on, from the height of its base centre: a lying bottle's base centre
    is one radius (times the sine of its tilt) above it (the closed loop's SeenObject)."""
    return base_z - radius * math.sin(min(tilt, math.pi / 2))
