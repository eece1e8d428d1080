"""Conversions between scenario bottles and qtree_relocation_msgs/ObjectArray, shared by every node.

Imports message types only (no rclpy): the node shells call these; the cores never see messages.
"""
from __future__ import annotations

import math
from typing import Iterable, Mapping

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, TransformStamped
from numpy.typing import ArrayLike
from qtree_relocation_msgs.msg import BlockerSet as BlockerSetMsg
from qtree_relocation_msgs.msg import LaneBlockers, ObjectArray, ObjectState

from .feasibility import BlockerSet
from .geometry import quat_xyzw
from .scenario import PALETTE, TARGET_COLOR, TARGET_RGB, ScenarioError, ShelfObject

BASE_FRAME = "j2s7s300_link_base"
# PlanFeasibility: ok=false with a message starting so means the planner's wall-clock safety net ran out before its
# work budget (a loaded machine): no answer, not UNFEASIBLE; ask again.
NO_ANSWER = "no answer: "


def bottle_to_msg(b: ShelfObject, z: float = 0.0) -> ObjectState:
    """A bottle standing upright; `z` is the height of its base (the shelf surface)."""
    m = ObjectState(id=b.id, label=b.label, weight=float(b.weight), is_target=b.is_target,
                    radius=float(b.radius), height=float(b.height))
    m.pose = Pose()
    m.pose.position.x, m.pose.position.y, m.pose.position.z = float(b.x), float(b.y), float(z)
    m.pose.orientation.w = 1.0
    return m


def bottles_to_msg(bottles: Iterable[ShelfObject], z: float, stamp: Time | None = None,
                   frame_id: str = BASE_FRAME) -> ObjectArray:
    """ObjectArray of `bottles` standing at height `z` in `frame_id`."""
    msg = ObjectArray()
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    msg.objects = [bottle_to_msg(b, z) for b in bottles]
    return msg


def msg_to_bottles(msg: ObjectArray) -> tuple[ShelfObject, ...]:
    """Bottles from a message; ScenarioError on NaN/Inf, empty or duplicate ids, or a bad weight."""
    out, seen = [], set()
    for k, o in enumerate(msg.objects):
        if not o.id:
            raise ScenarioError(f"objects[{k}]: empty id")
        if o.id in seen:
            raise ScenarioError(f"objects[{k}]: duplicate id {o.id!r}")
        seen.add(o.id)
        p = o.pose.position
        vals = (p.x, p.y, p.z, o.radius, o.height, o.weight)
        if not all(math.isfinite(v) for v in vals):
            raise ScenarioError(f"object {o.id!r}: non-finite pose or size")
        if o.radius <= 0 or o.height <= 0:
            raise ScenarioError(f"object {o.id!r}: radius and height must be positive")
        if not o.is_target and not 0.0 < o.weight <= 1.0:
            raise ScenarioError(f"object {o.id!r}: weight must be in (0, 1], got {o.weight}")
        rgb = TARGET_RGB if o.label == TARGET_COLOR else PALETTE.get(o.label, (0.5, 0.5, 0.5))
        out.append(ShelfObject(o.id, o.label, rgb, o.weight if not o.is_target else 1.0,
                          p.x, p.y, o.radius, o.height, o.is_target))
    if sum(b.is_target for b in out) != 1:
        raise ScenarioError("the scene must contain exactly one target")
    return tuple(out)


def transform_msg(t: ArrayLike, parent: str, child: str, stamp: Time | None = None) -> TransformStamped:
    """geometry_msgs/TransformStamped of the 4x4 pose `t` of `child` in `parent` (as tf2 publishes it)."""
    m = TransformStamped()
    if stamp is not None:
        m.header.stamp = stamp
    m.header.frame_id, m.child_frame_id = parent, child
    tr = m.transform.translation
    t = np.asarray(t, float)
    tr.x, tr.y, tr.z = (float(v) for v in t[:3, 3])
    r = m.transform.rotation
    r.x, r.y, r.z, r.w = quat_xyzw(t[:3, :3])
    return m


def blockers_to_msgs(blockers: Iterable[BlockerSet]) -> list[BlockerSetMsg]:
    """FeasibilityAnswer.blockers -> PlanFeasibility's `blockers` (ids sorted)."""
    return [BlockerSetMsg(lane=b.lane, object_ids=sorted(b.objects), certain=bool(b.certain)) for b in blockers]


def blockers_from_msgs(msgs: Iterable[BlockerSetMsg]) -> tuple[BlockerSet, ...]:
    """PlanFeasibility's `blockers` -> FeasibilityAnswer.blockers."""
    return tuple(BlockerSet(frozenset(m.object_ids), bool(m.certain), m.lane) for m in msgs)


def lanes_to_msgs(lanes: Mapping[str, Iterable[BlockerSet]]) -> list[LaneBlockers]:
    """object -> its lanes' BlockerSets (MotionPlanner.lane_blockers) -> PlanFeasibility's `lanes`."""
    return [LaneBlockers(object_id=o, lanes=blockers_to_msgs(sets)) for o, sets in sorted(lanes.items())]


def lanes_from_msgs(msgs: Iterable[LaneBlockers]) -> dict[str, tuple[BlockerSet, ...]]:
    """PlanFeasibility's `lanes` -> object -> its lanes' BlockerSets."""
    return {m.object_id: blockers_from_msgs(m.lanes) for m in msgs}
