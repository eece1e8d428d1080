"""Which bottles block each grasp lane: the grasp/approach screen of feasibility (paper Sect. 4.1,
step 1) asked per bottle instead of once for all.

A lane is one approach yaw of `grasp.grasp_yaw_tiers` (both tiers; a box's face yaws). `planning.pick.candidates` keeps
a lane when the hand proxy is clear at its pre-grasp and along the straight approach (the grasped bottle ignored for
palm and fingers on the approach). Collision of the proxy with a set of obstacles is the OR of its collisions with each
of them, so the lane's blockers are exact: the bottles the proxy meets there, each tested alone. The lane passes the
screen with `removed` gone exactly when all of its blockers are in `removed` (a *certain* BlockerSet). A lane the proxy
cannot use whatever is removed (out of the planner's workspace or reach, a board, the grasped bottle itself in the way)
is no lane. Computed once per (scene, object) with every bottle present; a query subtracts its removed set.

When the screen passes and STPIK or RRT-Connect still fail, the lane gets an *uncertain* set: the bottles within
SUSPECT_MARGIN of the proxy along it (suspects, not a claim).
"""
from __future__ import annotations

import weakref
from typing import Iterable, Protocol

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import BlockerSet
from relocation_common.scenario import Scenario
from stpik_motion_planner.model.collision import CollisionScene, HandProxy, ObstacleSet
from stpik_motion_planner.model.grasp import Grasp, Pose, WorkspaceError, pose_matrix, side_grasp

Lanes = tuple[tuple[Grasp, frozenset[str]], ...]  # (grasp, its blockers with every bottle present) per lane
SUSPECT_MARGIN = 0.03  # m added to the hand proxy's inflation to name the suspects of an STPIK/RRT failure

# scene (replaced when the planner's scenario changes) -> {(object, screen parameters, margin): lanes}
_CACHE: weakref.WeakKeyDictionary[CollisionScene, dict[tuple[object, ...], Lanes]] = weakref.WeakKeyDictionary()


class ScreenSettings(Protocol):
    """The planner's settings the screen reads (planning.params.PlannerParams)."""

    @property
    def n_yaws(self) -> int:
        """Approach yaws of the first tier."""

    @property
    def max_yaw(self) -> float:
        """The first tier's widest yaw (rad)."""

    @property
    def wide_yaws(self) -> int:
        """Approach yaws of the second tier (0: none)."""

    @property
    def wide_max_yaw(self) -> float:
        """The second tier's widest yaw (rad)."""

    @property
    def pre_grasp_distance(self) -> float:
        """m back along the approach."""

    @property
    def resolution(self) -> float:
        """m between the proxy's poses along a path."""


class Box(Protocol):
    """The Cartesian planner's box (planning.rrt.CartesianRRT)."""

    def contains(self, pose: Pose) -> bool:
        """The pose is inside the box."""


class Screened(Protocol):
    """What the screen reads of the planner (planning.context.PlanningContext, a layer above)."""

    @property
    def params(self) -> ScreenSettings:
        """The planner's settings."""

    @property
    def scenario(self) -> Scenario:
        """The scene's shelf and bottles."""

    @property
    def scene(self) -> CollisionScene:
        """The collision scene with every bottle present (the cache's key)."""

    @property
    def hand(self) -> HandProxy:
        """The Cartesian planner's hand proxy."""

    @property
    def hand_margin(self) -> float:
        """Its inflation (m)."""

    @property
    def rrt(self) -> Box:
        """The Cartesian planner."""

    def all_yaws(self, object_id: str) -> list[float]:
        """Every approach yaw of the object of both tiers, in the order they are tried."""

    def not_graspable(self, object_id: str) -> str:
        """Why the side grasp cannot take `object_id` ('' if it may)."""

    @property
    def ceiling_clearance(self) -> float:
        """What the hand keeps under the board above at a grasp from above."""

    def grasp_skip(self, object_id: str) -> dict[str, frozenset[str]]:
        """What the hand may touch on the straight approach to the grasp of `object_id` (the object; the board a
        lying one lies on: the fingers, or the whole hand for a grasp along its axis)."""


def _lanes(planner: Screened, object_id: str) -> list[Grasp]:
    """The object's grasps for every yaw inside the arm's reach and the Cartesian planner's box."""
    p = planner.params
    out = []
    for yaw in planner.all_yaws(object_id):
        try:
            g = side_grasp(planner.scenario, object_id, yaw, p.pre_grasp_distance, planner.ceiling_clearance)
        except WorkspaceError:
            continue
        if planner.rrt.contains(g.pre_grasp[:4 if len(g.pre_grasp) < 5 else 3]):  # from above: any yaw
            out.append(g)
    return out


def _blocked(planner: Screened, hand: HandProxy, g: Grasp, obs: ObstacleSet) -> bool:
    """The screen of one lane against `obs`: the proxy meets it at the pre-grasp or along the approach."""
    skip = planner.grasp_skip(g.object_id)
    return hand.collides(*pose_matrix(g.pre_grasp), obs) or not hand.path_clear([g.pre_grasp, g.grasp], obs,
                                                                                planner.params.resolution, skip)


def _near(hand: HandProxy, g: Grasp, obs: ObstacleSet) -> list:
    """Obstacles whose box is within the proxy's reach of the lane (broad phase)."""
    ends = np.array([g.pre_grasp[:3], g.grasp[:3]])
    reach = float(np.max(np.linalg.norm(np.vstack([hand.p0, hand.p1]), axis=1)) + np.max(hand.reach)) + rd.D67
    lo, hi = ends.min(axis=0) - reach, ends.max(axis=0) + reach
    keep = np.all((obs.lo <= hi) & (obs.hi >= lo), axis=1)
    return [o for o, k in zip(obs.items, keep) if k]


def _lane_blockers(planner: Screened, hand: HandProxy, g: Grasp) -> frozenset[str] | None:
    """The bottles the proxy meets on this lane with every bottle present; None if no removal can clear it."""
    scene = planner.scene
    fixed = ObstacleSet(scene.boards + scene.placed)
    if _blocked(planner, hand, g, fixed):
        return None
    everything = scene.obstacles()
    if not _blocked(planner, hand, g, everything):
        return frozenset()
    # the proxy's contact with a set of obstacles is the OR of its contacts with each: one pass collects them all
    skip = planner.grasp_skip(g.object_id)
    near = ObstacleSet([o for o in _near(hand, g, everything) if o.object_id in scene.bottles])
    met = hand.hits(*pose_matrix(g.pre_grasp), near) | hand.path_hits([g.pre_grasp, g.grasp], near,
                                                                       planner.params.resolution, skip)
    hits = frozenset(str(near.items[k].object_id) for k in met)
    return None if g.object_id in hits else hits


def static_lanes(planner: Screened, object_id: str, margin: float = 0.0) -> Lanes:
    """(grasp, blockers with every bottle present) of each lane some removal can clear, for the proxy inflated
    by `margin` more than the planner's; cached per scene."""
    p = planner.params
    key = (object_id, p.n_yaws, p.max_yaw, p.wide_yaws, p.wide_max_yaw, p.pre_grasp_distance, planner.hand_margin,
           p.resolution, margin)
    table = _CACHE.setdefault(planner.scene, {})
    got = table.get(key)
    if got is None:
        hand = planner.hand if margin == 0.0 else HandProxy(planner.hand_margin + margin)
        got = tuple((g, b) for g in _lanes(planner, object_id)
                    for b in [_lane_blockers(planner, hand, g)] if b is not None)
        table[key] = got
    return got


def _name(g: Grasp) -> str:
    return f"yaw {g.yaw:+.2f}"


def lane_blockers(planner: Screened, removed: Iterable[str] = frozenset()) -> dict[str, tuple[BlockerSet, ...]]:
    """Every object still on the shelf -> its lanes' certain blocker sets with `removed` gone (an empty tuple:
    no lane can ever be cleared, as for a lying bottle). No motion planning: the screen only."""
    gone = frozenset(planner.scenario.check_ids(removed))
    return {b.id: () if planner.not_graspable(b.id) else
            tuple(BlockerSet(bl - gone, True, _name(g)) for g, bl in static_lanes(planner, b.id))
            for b in planner.scenario.objects if b.id not in gone}


def answer_blockers(planner: Screened, object_id: str, removed: frozenset[str]) -> tuple[BlockerSet, ...]:
    """The blockers of an unfeasible answer: certain sets for the lanes the screen rejects; for a lane it passes
    (so STPIK or RRT-Connect failed there), an uncertain set of the bottles near it. Empty: no lane at all."""
    if planner.not_graspable(object_id):  # lying or off the shelf: no lane at all
        return ()
    suspects = {g.yaw: bl for g, bl in static_lanes(planner, object_id, SUSPECT_MARGIN)}
    out = []
    for g, bl in static_lanes(planner, object_id):
        left = bl - removed
        if left:
            out.append(BlockerSet(left, True, _name(g)))
        else:
            out.append(BlockerSet(suspects.get(g.yaw, frozenset()) - removed, False, _name(g)))
    return tuple(out)
