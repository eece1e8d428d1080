"""The geometry of a push (planning/push/): a standing cylinder slid along the top shelf by the closed finger tips.

The hand comes in horizontally (or tilted down by `pitch`, grasp.tool_rotation) along the push direction `u` (yaw
`yaw`), its fingers closed on nothing (collision.closed_fingers): the three tips lead, about 2 mm from the tool axis
and 20 mm beyond the grasp centre, fingers 2 and 3 one above the other. The tips touch the cylinder's side on the
line through its axis; the push is quasi-static (no rotation kept: a cylinder's pose is its axis), so the object
ends translated by the distance the tips moved after the contact. The contact geometry uses the simulator's finger
radius (robot_description.FINGER_RADIUS), where the tips really are; the collision checks keep the planner's
conservative finger capsules.
"""
from __future__ import annotations

import dataclasses
import math

import fcl
import numpy as np

from relocation_common import robot_description as rd
from relocation_common.scenario import Scenario, ShelfObject
from stpik_motion_planner.model.collision import CollisionScene, closed_fingers, cylinder
from stpik_motion_planner.model.grasp import tool_rotation

SWEEP_STEP = 0.005  # m between the poses of the pushed object checked along its sweep


def tips(yaw: float, pitch: float) -> np.ndarray:
    """The closed finger tips (their end centres), one row per finger, relative to the tool origin in the base frame
    for a tool at (yaw, pitch)."""
    rot = tool_rotation(yaw, pitch)
    return np.array([rot @ (s.p1 - np.array([0.0, 0.0, rd.D67])) for s in closed_fingers().values()])


def contact_pose(o: ShelfObject, top_z: float, yaw: float, pitch: float, height: float, gap: float
                 ) -> tuple[float, float, float, float, float]:
    """The tool pose (x, y, z, yaw, pitch) whose leading finger tip is `gap` short of the side of the standing
    cylinder `o` on the line through its axis along the push direction `yaw`, that tip `height` above the board
    (`top_z`); a horizontal hand (pitch 0) has fingers 2 and 3 22 mm above and below it."""
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    t = tips(yaw, pitch)
    lead = t[int(np.argmax(t @ u))]
    ahead = float(lead @ u) + rd.FINGER_RADIUS  # the tips' front beyond the tool origin along u
    side = lead - (lead @ u) * u  # the leading tip off the push line (across it and up): the tool is moved back by it
    across = side - side[2] * np.array([0.0, 0.0, 1.0])
    x, y = o.x - u[0] * (o.radius + gap + ahead) - across[0], o.y - u[1] * (o.radius + gap + ahead) - across[1]
    return (x, y, top_z + height - side[2], yaw, pitch)


def moved(scenario: Scenario, object_id: str, x: float, y: float) -> Scenario:
    """The scenario with `object_id` standing at (x, y) (the push's predicted end pose)."""
    objs = tuple(dataclasses.replace(o, x=x, y=y) if o.id == object_id else o for o in scenario.objects)
    return dataclasses.replace(scenario, objects=objs, _by_id={})


def sweep_problem(scene: CollisionScene, o: ShelfObject, end: tuple[float, float], present: frozenset[str],
                  margin: float) -> str:
    """Why the standing cylinder `o` cannot slide straight to `end` ('' if it can): its footprint, `margin` wider,
    off the top shelf (or into a side or back panel) at the end, or coming closer than `margin` to one of the
    `present` objects (ids of `scene`'s top-shelf objects) on the way, checked every SWEEP_STEP; an object already
    nearer than `margin` (the one the push clears for, beside it) may not come nearer than it stands."""
    s = scene.scenario.shelf
    r = o.radius + margin
    if not (s.x_front + r <= end[0] <= s.x_back - r and s.y_min + r <= end[1] <= s.y_max - r):
        return f"{o.id} would leave the shelf ({end[0]:.3f}, {end[1]:.3f}; {margin * 1000:.0f} mm margin)"
    others = [scene.bottles[i] for i in sorted(present) if i != o.id and i in scene.bottles]
    start = np.array([o.x, o.y])
    n = max(1, int(math.ceil(float(np.linalg.norm(np.asarray(end) - start)) / SWEEP_STEP)))
    req = fcl.DistanceRequest()
    bound: dict[str, float] = {}
    for k in range(n + 1):
        x, y = start + (np.asarray(end) - start) * (k / n)
        c = cylinder("swept", o.id, float(x), float(y), s.top_z + 0.001, o.radius, o.height - 0.002)
        for other in others:
            d = fcl.distance(c.obj, other.obj, req, fcl.DistanceResult())
            key = str(other.object_id)
            if key not in bound:
                bound[key] = min(margin, d) - 1e-4
            if d < bound[key]:
                return f"{o.id} would come within {margin * 1000:.0f} mm of {other.object_id} on the way"
    return ""
