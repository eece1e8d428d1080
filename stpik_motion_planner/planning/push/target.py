"""Where a push takes the object (the package docstring, step 1): the candidates (direction, distance) whose end
pose keeps the object on the shelf, sweeps clear of the others, and opens a lane of the object the push clears for
(model/blockers.py's screen on the scene with the object moved), ordered lexicographically: first those that open a
lane then free of every other object (the side grasp of C needs no further relocation), then the least distance;
the refusals that hold whatever the direction."""
from __future__ import annotations

import math

from relocation_common.scenario import Scenario
from stpik_motion_planner.model.blockers import static_lanes
from stpik_motion_planner.model.collision import CollisionScene
from stpik_motion_planner.model.push import ROLL, SLIDE, moved, sweep_problem
from stpik_motion_planner.planning.context import PlanningContext

LYING_OFF = {"push.slide": "a slid one rolls on once the hand retreats where the bottles have no rolling friction",
             "push.roll": "a rolled one wedges the hand: the palm's bound puts the tips above its axis"}  # push.md
BACKWARD = 3 * math.pi / 4  # rad: the push directions of a lying cylinder tried, at most this far from straight back
# (+x): the hand comes from the shelf's open front, and beside the object at most


def lying_directions(ctx: PlanningContext, axis: float) -> list[tuple[float, str]]:
    """[(push direction, kind)] of a cylinder lying flat with its axis at yaw `axis`: along the axis both ways (a
    slide) when push.slide, across it both ways (a roll) when push.roll; those at most BACKWARD from +x."""
    p = ctx.params.push
    out = [(axis + k * math.pi / 2, ROLL if k % 2 else SLIDE) for k in range(4)]
    out = [(math.remainder(a, 2 * math.pi), kd) for a, kd in out if (p.slide if kd == SLIDE else p.roll)]
    return [(a, kd) for a, kd in out if abs(a) <= BACKWARD + 1e-9]


def box_directions(o_yaw: float) -> list[float]:
    """The push directions of a box: its faces' normals (a push through the middle of a face slides it without
    turning it), those at most BACKWARD from +x."""
    out = [math.remainder(o_yaw + k * math.pi / 2, 2 * math.pi) for k in range(4)]
    return [a for a in out if abs(a) <= BACKWARD + 1e-9]


def end_xy(x: float, y: float, yaw: float, distance: float) -> tuple[float, float]:
    """Where the pushed object's axis ends: (x, y) translated by `distance` along `yaw` (quasi-static)."""
    return x + distance * math.cos(yaw), y + distance * math.sin(yaw)


class _Moved:
    """The lane screen's view of the planner (blockers.Screened) with the pushed object at its end pose."""

    def __init__(self, ctx: PlanningContext, scenario: Scenario) -> None:
        self.params, self.hand, self.hand_margin, self.rrt = ctx.params, ctx.hand, ctx.hand_margin, ctx.rrt
        self.scenario = scenario
        self.scene = CollisionScene(scenario, (), ctx.lying, ctx.gone)
        self.all_yaws, self.not_graspable = ctx.all_yaws, ctx.not_graspable
        self.ceiling_clearance, self.grasp_skip = ctx.ceiling_clearance, ctx.grasp_skip


def refusal(ctx: PlanningContext, object_id: str, clear_for: str, removed: frozenset[str]) -> str:
    """Why no push of `object_id` can clear the lanes of `clear_for` whatever its direction ('' if one may)."""
    o = ctx.scenario.object(object_id)
    if object_id in ctx.gone:
        return f"no push: {object_id} left the shelf"
    if object_id in ctx.lying:
        return f"no push: {object_id} leans (the push slides a standing or a flat lying cylinder, or a box)"
    if o.shape not in ("cylinder", "box") or o.conservative:
        return (f"no push: {object_id} is not a cylinder or a box (the push slides a standing or a flat lying "
                "cylinder, or a box)")
    if o.lying and not lying_directions(ctx, o.yaw):
        p = ctx.params.push
        off = [k for k, on in (("push.slide", p.slide), ("push.roll", p.roll)) if not on]
        return (f"no push: {object_id} lies ({', '.join(off) or 'no direction from the front'}"
                f"{' off: ' + '; '.join(LYING_OFF[k] for k in off) + ' (docs/bench/push.md)' if off else ''})")
    if not any(object_id in bl for _, bl in static_lanes(ctx, clear_for)):
        return f"no push: no grasp lane of {clear_for} is blocked by {object_id}"
    return ""


def opened_lane(ctx: PlanningContext, clear_for: str, removed: frozenset[str], object_id: str,
                after: _Moved) -> tuple[str, frozenset[str]]:
    """(the name of a lane of `clear_for` that `object_id` blocks where it stands and not at its end pose, with no
    blocker the lane did not have, '' if none; the objects but `removed` that still block it there): a lane then
    free is named when there is one."""
    before = {g.yaw: bl for g, bl in static_lanes(ctx, clear_for)}
    found = []
    for g, bl in static_lanes(after, clear_for):
        was = before.get(g.yaw)
        if was is not None and object_id in was and object_id not in bl and bl - removed <= was - removed:
            found.append((g.yaw, f"yaw {g.yaw:+.2f}", bl - removed))
    if not found:
        return "", frozenset()
    _, lane, held = min(found, key=lambda f: (bool(f[2]), f[1]))
    return lane, held


def candidates(ctx: PlanningContext, object_id: str, clear_for: str, removed: frozenset[str]
               ) -> tuple[list[tuple[float, float, str, frozenset[str]]], str]:
    """([(yaw, distance, lane opened, the objects still blocking it)] in the order tried, why none if empty):
    lexicographically, the pushes that open a lane then free of every other object first (`removed` gone: the side
    grasp of `clear_for` needs no further relocation), then the least distance, then push.directions' order. The
    shortest push that opens a lane still held by another object is tried only after every one that opens a free
    lane."""
    p = ctx.params.push
    o, c = ctx.scenario.object(object_id), ctx.scenario.object(clear_for)
    side = o.y - c.y
    signs = [1.0 if side > 0 else -1.0] if abs(side) > 1e-3 else [1.0, -1.0]
    present = frozenset(b.id for b in ctx.scenario.objects) - removed - ctx.gone
    if o.shape == "box":
        yaws, distances = box_directions(o.yaw), sorted(set(p.distances) | set(p.lying_distances))
    elif o.lying:
        yaws, distances = [a for a, _ in lying_directions(ctx, o.yaw)], list(p.lying_distances)
    else:
        yaws, distances = [sg * a for a in p.directions for sg in (signs if a else [1.0])], list(p.distances)
    out, why = [], {}
    for d in distances:
        for yaw in yaws:
            end = end_xy(o.x, o.y, yaw, d)
            bad = sweep_problem(ctx.scene, o, end, present, p.sweep_margin)
            if bad:
                why[(yaw, d)] = bad
                continue
            lane, held = opened_lane(ctx, clear_for, removed, object_id,
                                     _Moved(ctx, moved(ctx.scenario, object_id, *end)))
            if not lane:
                why[(yaw, d)] = f"{clear_for}'s lanes still blocked by {object_id}"
                continue
            out.append((yaw, d, lane, held))
    if out:
        return sorted(out, key=lambda c: bool(c[3])), ""  # stable: the least distance next, then the direction
    kinds = sorted(set(why.values()))
    return [], f"no push direction clears {clear_for}'s lanes: {'; '.join(kinds[:3])}"
