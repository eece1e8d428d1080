"""A bottle's orientation as ObjectState carries it (pose.orientation, a unit quaternion): how far it is tipped and
the surface it rests on. One place for the task planner's checks (qtree_task_planner.executive.closed_loop) and the
motion planner's scene (stpik_motion_planner.model.scene_update); the rotations themselves are
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
