"""A bottle's orientation: UPRIGHT_TILT, the one bound between standing and lying (the object model's `lying`,
shelf_object.at_pose), how far a pose is tipped, and the surface a bottle rests on from its base centre (the closed
loop's SeenObject). Messages are read through relocation_common.ros_conversions only; the rotations themselves are
relocation_common.geometry's."""
from __future__ import annotations

import math

from . import geometry

UPRIGHT_TILT = math.radians(20)  # rad: a bottle whose axis is tilted more from the vertical is not standing


def tilt_of_quaternion(w: float, x: float, y: float, z: float) -> float:
    """Angle (rad) between a body's z axis and the vertical, from its orientation (ObjectState.pose; a zero
    quaternion is upright)."""
    return geometry.tilt(geometry.wxyz_matrix((w, x, y, z)))


def support_height(base_z: float, radius: float, tilt: float) -> float:
    """Height of the surface a bottle rests on, from the height of its base centre: a lying bottle's base centre
    is one radius (times the sine of its tilt) above it."""
    return base_z - radius * math.sin(min(tilt, math.pi / 2))
