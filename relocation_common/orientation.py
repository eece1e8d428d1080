"""A bottle's orientation as ObjectState carries it (pose.orientation, a unit quaternion): how far it is tipped,
its axis, the surface it rests on. One place for the task planner's checks (qtree_task_planner.executive.closed_loop)
and
the motion planner's scene (stpik_motion_planner.model.scene_update, collision.lying_cylinder)."""
from __future__ import annotations

import math

import numpy as np

UPRIGHT_TILT = math.radians(20)  # rad: a bottle whose axis is tilted more from the vertical is not standing


def tilt_of_quaternion(w: float, x: float, y: float, z: float) -> float:
    """Angle (rad) between a body's z axis and the vertical, from its orientation (ObjectState.pose)."""
    n = w * w + x * x + y * y + z * z
    c = 1.0 - 2.0 * (x * x + y * y) / n if n > 0 else 1.0
    return math.acos(max(-1.0, min(1.0, c)))


def quaternion_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    """The 3x3 rotation of a quaternion (normalised first; a zero one is the identity)."""
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if n == 0:
        return np.eye(3)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def support_height(base_z: float, radius: float, tilt: float) -> float:
    """Height of the surface a bottle rests on, from the height of its base centre: a lying bottle's base centre
    is one radius (times the sine of its tilt) above it."""
    return base_z - radius * math.sin(min(tilt, math.pi / 2))
