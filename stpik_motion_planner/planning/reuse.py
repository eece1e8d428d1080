"""The objects a pick's motion comes near (relocation_common.feasibility, "Reuse"; docs/motion_planner.md, "Reuse
across answers"): the answer's `near` set.

An object enters a check of a pick only within the widest band any check of it looks at (PlannerParams.
checked_distance: the hand proxy's inflation in the Cartesian planner, STPIK's candidate band clearance + buffer).
`near_objects` lists every top-shelf bottle, removed or not, whose place some arm capsule (at each IK step of the
tracked motion) or the hand proxy (along the tool path, at the Cartesian planner's resolution) comes within
`reuse_distance` (>= that band) of, by axis-aligned boxes (a superset of the true distances: never too few). A
bottle outside that set took part in no check of the motion whether it stood there or not, so the motion stays valid
and is tracked identically in any scene that differs from the question's only in such bottles.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from relocation_common import robot_description as rd
from stpik_motion_planner.model.collision import ObstacleSet
from stpik_motion_planner.planning.context import PlanningContext


def near_objects(ctx: PlanningContext, object_id: str, steps: Sequence[np.ndarray], tool_path: Sequence[np.ndarray]
                 ) -> frozenset[str]:
    """The bottles (other than `object_id`, removed or not) within reuse_distance of the arm at the IK `steps` or of
    the hand proxy along `tool_path` ((x, y, z, yaw) poses)."""
    d = ctx.params.reuse_distance
    bottles = [o for i, o in ctx.scene.bottles.items() if i != object_id]
    if not bottles:
        return frozenset()
    obs = ObstacleSet(bottles)
    arm_lo, arm_hi = arm_boxes(ctx, steps)
    hand_lo, hand_hi = proxy_boxes(ctx, tool_path)
    lo, hi = np.vstack([arm_lo, hand_lo - d]), np.vstack([arm_hi, hand_hi + d])
    gap = np.maximum(np.maximum(obs.lo[None] - hi[:, None], lo[:, None] - obs.hi[None]), 0.0)
    near = np.nonzero((np.einsum("ijk,ijk->ij", gap, gap) < d * d).any(axis=0))[0]
    return frozenset(str(bottles[k].object_id) for k in near)


def proxy_boxes(ctx: PlanningContext, tool_path: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned boxes (lo, hi: one row per shape and pose) of the Cartesian planner's hand proxy, uninflated,
    at every pose its checks visit along the polyline `tool_path` (every `resolution` m, as HandProxy.path_clear)."""
    proxy, res = ctx.hand, ctx.params.resolution
    poses = []
    for a, b in zip(tool_path[:-1], tool_path[1:]):
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = max(1, int(math.ceil(max(np.linalg.norm(b[:3] - a[:3]), 0.25 * abs(b[3] - a[3])) / res)))
        poses.append(a + (b - a) * (np.arange(n + 1) / n)[:, None])
    pose = np.vstack(poses)
    c, s = np.cos(pose[:, 3]), np.sin(pose[:, 3])
    rot = np.zeros((len(pose), 3, 3))  # grasp.side_rotation of each yaw
    rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 0], rot[:, 1, 2], rot[:, 2, 1] = -s, c, c, s, 1.0
    p7 = pose[:, :3] - rot[:, :, 2] * rd.D67  # link 7's origin (HandProxy.hits)
    p0 = np.einsum("nij,cj->nci", rot, proxy.p0) + p7[:, None]
    p1 = np.einsum("nij,cj->nci", rot, proxy.p1) + p7[:, None]
    rad = np.array([sp.radius for sp in proxy.specs])[None, :, None]
    return (np.minimum(p0, p1) - rad).reshape(-1, 3), (np.maximum(p0, p1) + rad).reshape(-1, 3)


def arm_boxes(ctx: PlanningContext, steps: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned boxes (lo, hi: one row per arm capsule and step) of the arm's capsules (robot_description.
    CAPSULES) at every configuration of `steps`: the frames of all steps first, then every capsule at once."""
    caps = rd.CAPSULES
    fids = sorted({ctx.kin.fid[c.link] for c in caps})
    row = np.array([fids.index(ctx.kin.fid[c.link]) for c in caps])
    frames = np.empty((len(steps), len(fids), 4, 4))
    omf = ctx.kin.data.oMf
    for s, q in enumerate(steps):
        ctx.kin.update(q, jacobians=False)
        for k, fid in enumerate(fids):
            frames[s, k] = omf[fid].homogeneous
    m = frames[:, row]  # steps x capsules x 4 x 4
    p0 = np.einsum("scij,cj->sci", m[..., :3, :3], np.array([c.p0 for c in caps])) + m[..., :3, 3]
    p1 = np.einsum("scij,cj->sci", m[..., :3, :3], np.array([c.p1 for c in caps])) + m[..., :3, 3]
    rad = np.array([c.radius for c in caps])[None, :, None]
    return (np.minimum(p0, p1) - rad).reshape(-1, 3), (np.maximum(p0, p1) + rad).reshape(-1, 3)
