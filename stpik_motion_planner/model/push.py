"""The geometry of a push (planning/push/): a cylinder slid along the top shelf by the closed finger tips, standing
or lying flat (its kind: `kind`; a lying one slid along its axis, the tips against its end cap, or rolled across it,
the tips against its side), or a box slid on its face, the tips against the middle of a side face.

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
from stpik_motion_planner.model.collision import CollisionScene, closed_fingers, cylinder, object_obstacle
from stpik_motion_planner.model.grasp import tool_rotation

PALM = next(c for c in rd.CAPSULES if c.name == "palm")  # the push's hand: its palm (motion.py's bound over the board)
SWEEP_STEP = 0.005  # m between the poses of the pushed object checked along its sweep
SLIDE, ROLL, STANDING, BOX = "slide", "roll", "standing", "box"


def kind(o: ShelfObject, yaw: float) -> str:
    """The kind of a push of `o` along `yaw`: a standing cylinder's; a lying one's along its axis (within 45 deg) a
    slide, across it a roll; a box's (slid on its face, along a face's normal: target.box_directions)."""
    if o.shape == "box":
        return BOX
    if not o.lying:
        return STANDING
    return SLIDE if abs(math.cos(yaw - o.yaw)) >= math.cos(math.pi / 4) else ROLL


def reach(o: ShelfObject, yaw: float) -> float:
    """m from the object's axis (a lying one's or a box's centre) to its side along the push direction `yaw`: the
    radius of a standing cylinder; of a lying one or a box, the support of its rectangle footprint (a lying one's:
    half its length along its axis, the radius across it)."""
    if o.shape == "box":
        return abs(math.cos(yaw - o.yaw)) * o.size[0] / 2 + abs(math.sin(yaw - o.yaw)) * o.size[1] / 2
    if not o.lying:
        return o.radius
    return abs(math.cos(yaw - o.yaw)) * o.height / 2 + abs(math.sin(yaw - o.yaw)) * o.radius


def tips(yaw: float, pitch: float, hand_roll: float = 0.0) -> np.ndarray:
    """The closed finger tips (their end centres), one row per finger, relative to the tool origin in the base frame
    for a tool at (yaw, pitch, hand_roll)."""
    rot = tool_rotation(yaw, pitch, hand_roll)
    return np.array([rot @ (s.p1 - np.array([0.0, 0.0, rd.D67])) for s in closed_fingers().values()])


def contact_pose(o: ShelfObject, top_z: float, yaw: float, pitch: float, height: float, gap: float,
                 hand_yaw: float | None = None, hand_roll: float = 0.0) -> tuple[float, ...]:
    """The tool pose (x, y, z, hand yaw, pitch, hand roll) whose leading finger tip is `gap` short of the side of the
    object `o` (reach: a lying cylinder's end cap or side, a box's face) on the line through its axis (centre) along
    the push direction `yaw`, that tip `height` above the board (`top_z`); the hand points along `hand_yaw` (default:
    the push's), turned `hand_roll` about its axis; a horizontal hand (pitch 0) has fingers 2 and 3 22 mm above and
    below it (rolled half a turn: below and above)."""
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    hand_yaw = yaw if hand_yaw is None else hand_yaw
    t = tips(hand_yaw, pitch, hand_roll)
    lead = t[int(np.argmax(t @ u))]
    ahead = float(lead @ u) + rd.FINGER_RADIUS  # the tips' front beyond the tool origin along u
    side = lead - (lead @ u) * u  # the leading tip off the push line (across it and up): the tool is moved back by it
    across = side - side[2] * np.array([0.0, 0.0, 1.0])
    r = reach(o, yaw)
    x, y = o.x - u[0] * (r + gap + ahead) - across[0], o.y - u[1] * (r + gap + ahead) - across[1]
    return (x, y, top_z + height - side[2], hand_yaw, pitch, hand_roll)


def leading(yaw: float, hand_yaw: float, hand_roll: float = 0.0) -> tuple[np.ndarray, float]:
    """(the leading finger tips' centres relative to the tool, one row each: those within 1 mm of the foremost along
    the push direction `yaw`; how far the tips lead the rest of the closed hand along it, m: the fingers' hinges
    and the palm, planner radii) for a horizontal hand pointing along `hand_yaw`, turned `hand_roll` about its axis. A
    push to the hand's right (yaw < hand_yaw) leads with fingers 2 and 3, one above the other, to its left with
    finger 1 alone (rolled half a turn: the other way round); turned more than about 1 rad from the hand, the hinges
    lead."""
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    rot = tool_rotation(hand_yaw, 0.0, hand_roll)
    t = tips(hand_yaw, 0.0, hand_roll)
    front = t @ u
    fingers = closed_fingers().values()
    tip_front = float(front.max()) + max(c.radius for c in fingers)
    rest = [(c.p0, c.radius) for c in fingers] + [(np.asarray(p, float), PALM.radius) for p in (PALM.p0, PALM.p1)]
    ahead = min(tip_front - (float(rot @ (p - np.array([0.0, 0.0, rd.D67])) @ u) + r) for p, r in rest)
    return t[front >= front.max() - 0.001], ahead


def moved(scenario: Scenario, object_id: str, x: float, y: float) -> Scenario:
    """The scenario with `object_id` at (x, y), standing or lying with its yaw (the push's predicted end pose)."""
    objs = tuple(dataclasses.replace(o, x=x, y=y) if o.id == object_id else o for o in scenario.objects)
    return dataclasses.replace(scenario, objects=objs, _by_id={})


def sweep_problem(scene: CollisionScene, o: ShelfObject, end: tuple[float, float], present: frozenset[str],
                  margin: float) -> str:
    """Why the cylinder `o` (standing, or lying: its rectangle) cannot slide straight to `end` ('' if it can): its
    footprint, `margin` wider, off the top shelf (or into a side or back panel) at the end, or coming closer than
    `margin` to one of the `present` objects (ids of `scene`'s top-shelf objects) on the way, checked every
    SWEEP_STEP; an object already nearer than `margin` (the one the push clears for, beside it) may not come nearer
    than it stands."""
    s = scene.scenario.shelf
    if not dataclasses.replace(o, x=end[0], y=end[1]).footprint(margin).inside(s.x_front, s.x_back, s.y_min, s.y_max):
        return f"{o.id} would leave the shelf ({end[0]:.3f}, {end[1]:.3f}; {margin * 1000:.0f} mm margin)"
    others = [scene.bottles[i] for i in sorted(present) if i != o.id and i in scene.bottles]
    start = np.array([o.x, o.y])
    n = max(1, int(math.ceil(float(np.linalg.norm(np.asarray(end) - start)) / SWEEP_STEP)))
    req = fcl.DistanceRequest()
    bound: dict[str, float] = {}
    for k in range(n + 1):
        x, y = start + (np.asarray(end) - start) * (k / n)
        at = dataclasses.replace(o, x=float(x), y=float(y))
        c = object_obstacle(at, s.top_z) if o.lying or o.shape == "box" else \
            cylinder("swept", o.id, float(x), float(y), s.top_z + 0.001, o.radius, o.height - 0.002)
        for other in others:
            d = fcl.distance(c.obj, other.obj, req, fcl.DistanceResult())
            key = str(other.object_id)
            if key not in bound:
                bound[key] = min(margin, d) - 1e-4
            if d < bound[key]:
                return f"{o.id} would come within {margin * 1000:.0f} mm of {other.object_id} on the way"
    return ""
