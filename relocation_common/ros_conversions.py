"""Conversions between the object model (relocation_common.shelf_object.ShelfObject) and
qtree_relocation_msgs/ObjectArray, shared by every node, and the other messages the nodes exchange.

Imports message types only (no rclpy): the node shells call these; the cores never see messages. ObjectState carries
the primitive as moveit_msgs/CollisionObject does (shape_msgs/SolidPrimitive, the pose at the primitive's centre):
`object_to_msg` and `msg_to_objects` are the one place that convention meets the object model's (x, y on the
support, `support_z`, `lying`, `yaw`); every producer and consumer of ObjectState goes through them.
"""
from __future__ import annotations

import math
from typing import Collection, Iterable, Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, TransformStamped
from numpy.typing import ArrayLike
from qtree_relocation_msgs.msg import BlockerSet as BlockerSetMsg
from qtree_relocation_msgs.msg import LaneBlockers, ObjectArray, ObjectState
from shape_msgs.msg import SolidPrimitive
from std_msgs.msg import ColorRGBA

from .feasibility import BlockerSet
from .geometry import quat_xyzw, quats_xyzw, xyzw_matrix
from .scenario import ID_PATTERN, PALETTE, TARGET_COLOR, TARGET_RGB, ScenarioError, ShelfObject
from .shelf_object import at_pose

BASE_FRAME = "j2s7s300_link_base"
# PlanFeasibility: ok=false with a message starting so means the planner's wall-clock safety net ran out before its
# work budget (a loaded machine): no answer, not UNFEASIBLE; ask again.
NO_ANSWER = "no answer: "
UNIT_TOL = 1e-3  # |1 - |q|| above this: the orientation is not a unit quaternion (refused)
COLOR_DECIMALS = 6  # ColorRGBA is float32: the colour comes back rounded to 1e-6 (0.85 -> 0.85)


def object_to_msg(o: ShelfObject) -> ObjectState:
    """ObjectState of an object (it must know its `support_z`): the primitive's centre and orientation as the pose,
    CYLINDER [height, radius] or BOX [x, y, z] as the shape."""
    m = ObjectState(id=o.id, label=o.label, weight=float(o.weight), weight_note=o.weight_note,
                    is_target=o.is_target, listed=o.listed, fit_rms=float(o.fit_rms), conservative=o.conservative)
    m.color = ColorRGBA(r=float(o.rgb[0]), g=float(o.rgb[1]), b=float(o.rgb[2]), a=1.0)
    c = o.centre()
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in c)
    q = m.pose.orientation
    q.x, q.y, q.z, q.w = quat_xyzw(o.rotation())
    if o.shape == "box":
        m.shape = SolidPrimitive(type=SolidPrimitive.BOX, dimensions=[float(v) for v in o.size])
    else:
        m.shape = SolidPrimitive(type=SolidPrimitive.CYLINDER, dimensions=[float(o.height), float(o.radius)])
    return m


def objects_to_msg(objects: Iterable[ShelfObject], stamp: Time | None = None,
                   frame_id: str = BASE_FRAME) -> ObjectArray:
    """ObjectArray of `objects` (object_to_msg) in `frame_id`."""
    msg = ObjectArray()
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    msg.objects = [object_to_msg(o) for o in objects]
    return msg


def msg_to_objects(msg: ObjectArray, listed_ids: Collection[str] | None = None,
                   require_target: bool = True) -> tuple[ShelfObject, ...]:
    """The objects of a message; ScenarioError (one line) on an empty, malformed or duplicate id, NaN/Inf, a shape
    other than a CYLINDER [height, radius] or BOX [x, y, z] with positive dimensions, an orientation that is not a
    unit quaternion, a weight outside (0, 1], or not exactly one target (`require_target` False: at most one, e.g.
    a scene in which the target is no longer seen). `listed_ids` (the scenario's ids): a listed object must be one
    of them, an unlisted one must not (perception names those u1, u2, ...)."""
    out: list[ShelfObject] = []
    seen: set[str] = set()
    for k, o in enumerate(msg.objects):
        if not o.id:
            raise ScenarioError(f"objects[{k}]: empty id")
        if not ID_PATTERN.fullmatch(o.id):
            raise ScenarioError(f"objects[{k}]: id {o.id[:40]!r} is not a letter then letters, digits or '_'")
        if o.id in seen:
            raise ScenarioError(f"objects[{k}]: duplicate id {o.id!r}")
        seen.add(o.id)
        out.append(_object(o, listed_ids))
    targets = sum(b.is_target for b in out)
    if targets > 1 or (require_target and targets != 1):
        raise ScenarioError(f"the scene must contain exactly one target, got {targets}")
    return tuple(out)


def _object(o: ObjectState, listed_ids: Collection[str] | None) -> ShelfObject:
    p, q, c = o.pose.position, o.pose.orientation, o.color
    if not all(math.isfinite(v) for v in (p.x, p.y, p.z, q.x, q.y, q.z, q.w, o.weight, o.fit_rms, c.r, c.g, c.b,
                                          *o.shape.dimensions)):
        raise ScenarioError(f"object {o.id!r}: non-finite pose, size, colour or weight")
    norm = math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2)
    if abs(norm - 1.0) > UNIT_TOL:
        raise ScenarioError(f"object {o.id!r}: orientation is not a unit quaternion (norm {norm:.4f})")
    dims = [float(v) for v in o.shape.dimensions]
    if o.shape.type == SolidPrimitive.CYLINDER and len(dims) == 2 and min(dims) > 0:
        shape, radius, height, size = "cylinder", dims[1], dims[0], (0.0, 0.0, 0.0)
    elif o.shape.type == SolidPrimitive.BOX and len(dims) == 3 and min(dims) > 0:
        shape, radius, height, size = "box", 0.0, dims[2], (dims[0], dims[1], dims[2])
    else:
        raise ScenarioError(f"object {o.id!r}: shape must be a CYLINDER [height, radius] or a BOX [x, y, z] with "
                            f"positive dimensions, got type {o.shape.type} {dims}")
    if not o.is_target and not 0.0 < o.weight <= 1.0:
        raise ScenarioError(f"object {o.id!r}: weight must be in (0, 1], got {o.weight}")
    if listed_ids is not None and o.listed != (o.id in listed_ids):
        raise ScenarioError(f"object {o.id!r}: " + ("listed, but the scenario does not list it" if o.listed else
                                                     "unlisted, but the scenario lists that id"))
    if c.a > 0:
        rgb = tuple(round(float(v), COLOR_DECIMALS) for v in (c.r, c.g, c.b))
    else:  # no colour given: the label's
        rgb = TARGET_RGB if o.label == TARGET_COLOR else PALETTE.get(o.label, (0.5, 0.5, 0.5))
    b = ShelfObject(o.id, o.label, (rgb[0], rgb[1], rgb[2]), o.weight if not o.is_target else 1.0, p.x, p.y, radius,
                    height, o.is_target, shape, size, listed=o.listed, weight_note=o.weight_note,
                    fit_rms=float(o.fit_rms), conservative=o.conservative)
    return at_pose(b, (p.x, p.y, p.z), xyzw_matrix((q.x, q.y, q.z, q.w)))


def transform_msg(t: ArrayLike, parent: str, child: str, stamp: Time | None = None) -> TransformStamped:
    """geometry_msgs/TransformStamped of the 4x4 pose `t` of `child` in `parent` (as tf2 publishes it)."""
    return transform_msgs([(parent, child, t)], stamp)[0]


def transform_msgs(transforms: Sequence[tuple[str, str, ArrayLike]], stamp: Time | None = None
                   ) -> list[TransformStamped]:
    """transform_msg of each (parent, child, 4x4 pose), the rotations converted together (geometry.quats_xyzw)."""
    poses = np.asarray([t for _, _, t in transforms], float).reshape(-1, 4, 4)
    quats = quats_xyzw(poses[:, :3, :3]) if len(poses) else np.zeros((0, 4))
    out = []
    for (parent, child, _), t, q in zip(transforms, poses, quats):
        m = TransformStamped()
        if stamp is not None:
            m.header.stamp = stamp
        m.header.frame_id, m.child_frame_id = parent, child
        tr, r = m.transform.translation, m.transform.rotation
        tr.x, tr.y, tr.z = (float(v) for v in t[:3, 3])
        r.x, r.y, r.z, r.w = (float(v) for v in q)
        out.append(m)
    return out


def blockers_to_msgs(blockers: Iterable[BlockerSet]) -> list[BlockerSetMsg]:
    """FeasibilityAnswer.blockers -> PlanFeasibility's `blockers` (ids sorted)."""
    return [BlockerSetMsg(lane=b.lane, object_ids=sorted(b.objects), certain=bool(b.certain)) for b in blockers]


def blockers_from_msgs(msgs: Iterable[BlockerSetMsg]) -> tuple[BlockerSet, ...]:
    """PlanFeasibility's `blockers` -> FeasibilityAnswer.blockers."""
    return tuple(BlockerSet(frozenset(m.object_ids), bool(m.certain), m.lane) for m in msgs)


def near_to_fields(near: frozenset[str] | None) -> tuple[bool, list[str]]:
    """FeasibilityAnswer.near -> PlanFeasibility's (near_known, near_ids) (ids sorted; None: unknown)."""
    return near is not None, sorted(near or ())


def near_from_fields(known: bool, ids: Iterable[str]) -> frozenset[str] | None:
    """PlanFeasibility's (near_known, near_ids) -> FeasibilityAnswer.near."""
    return frozenset(ids) if known else None


def lanes_to_msgs(lanes: Mapping[str, Iterable[BlockerSet]]) -> list[LaneBlockers]:
    """object -> its lanes' BlockerSets (MotionPlanner.lane_blockers) -> PlanFeasibility's `lanes`."""
    return [LaneBlockers(object_id=o, lanes=blockers_to_msgs(sets)) for o, sets in sorted(lanes.items())]


def lanes_from_msgs(msgs: Iterable[LaneBlockers]) -> dict[str, tuple[BlockerSet, ...]]:
    """PlanFeasibility's `lanes` -> object -> its lanes' BlockerSets."""
    return {m.object_id: blockers_from_msgs(m.lanes) for m in msgs}


def moved_to_fields(moved: Mapping[str, tuple[float, float]]) -> tuple[list[str], list[Point]]:
    """object -> (x, y) on the top shelf -> PlanFeasibility's (moved_ids, moved_to) (ids sorted; z 0)."""
    ids = sorted(moved)
    return ids, [Point(x=float(moved[i][0]), y=float(moved[i][1]), z=0.0) for i in ids]


def moved_from_fields(ids: Sequence[str], points: Sequence[Point]) -> dict[str, tuple[float, float]]:
    """PlanFeasibility's (moved_ids, moved_to) -> object -> (x, y); ValueError when they do not pair up (lengths
    differ, an id twice)."""
    if len(ids) != len(points):
        raise ValueError(f"moved_ids ({len(ids)}) and moved_to ({len(points)}) must pair up, one position per id")
    if len(set(ids)) != len(ids):
        raise ValueError(f"moved_ids names an object twice: {sorted(ids)}")
    return {str(i): (float(p.x), float(p.y)) for i, p in zip(ids, points)}
