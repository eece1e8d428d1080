"""The carry of a relocation: from the grasp, lift, out of the shelf, in to the slot on the bottom shelf, release,
and the retreat to the staging pose in front of the slot (paper Sect. 4.1, the relocation after the pick).

The bottle (or box, square to the hand: model.grasp) is modelled at its real size on the hand (STPIK's arm geometry and
the Cartesian planner's hand proxy; `carried_shape`) with its own clearance bound `carried_clearance`; it may touch only
the board it stands on, and only while it is lifted straight up off it (`lift` >= carried_clearance + stpik.act, so it
clears the board before any motion out of the shelf). Then straight back out of the shelf at that height (or RRT-Connect
if that is blocked), to the staging pose in front of the slot, and straight in at the release height.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.scenario import ShelfObject
from stpik_motion_planner.model.collision import (
    CARRIED,
    HAND_PARTS,
    PENETRATION,
    ArmGeometry,
    CapsuleSpec,
    HandProxy,
    ObstacleSet,
    capsule_spec,
    carried_bottle,
    carried_box,
)
from stpik_motion_planner.model.grasp import (
    Pose,
    WorkspaceError,
    along_axis_raise,
    along_axis_standoff,
    check_pose,
    exit_pose,
    face_yaws,
    grasp_extent,
    grasp_standoff,
    held_standoff,
    held_tilt,
    place_poses,
    pose_matrix,
    pose_pitch,
    stand_up_poses,
    tool_angles,
)
from stpik_motion_planner.planning.context import Placed, PlanningContext, check_q, draw_seed
from stpik_motion_planner.planning.results import PlanningError, QueryStats, Segment
from stpik_motion_planner.planning.stpik import StpikResult
from stpik_motion_planner.planning.trajectory import Trajectory

START_RELIEF = 0.0005  # m: margin under a tight start's distance (carried_models, carried_hand)


@dataclass
class CarryGoal:
    """Where a carry takes the bottle: slot `slot_index` at `slot` (x, y), lifted by `lift`, the staging pose in
    front of the slot and the place pose in it (x, y, z, yaw); `what` names the carry in errors."""

    what: str
    slot_index: int
    slot: tuple[float, float]
    lift: float
    stage: np.ndarray
    place: np.ndarray


def carry_goal(ctx: PlanningContext, object_id: str, slot_index: int, grasp_yaw: float) -> CarryGoal:
    """The goal of the carry of `object_id`, grasped at approach yaw `grasp_yaw` (the face of a box it holds), to
    `scenario.slot(slot_index)`, checked before anything is planned: PlanningError naming the carry for a slot or
    a pose out of reach (or a bottle too tall to carry)."""
    what = f"carry of {object_id!r} to slot {slot_index}"
    try:
        slot = ctx.scenario.slot(slot_index)
        lift, release = ctx.carry_heights(object_id)
        stage, place = (np.array(x) for x in place_poses(ctx.scenario, object_id, slot, release,
                                                           ctx.params.stage_distance, grasp_yaw,
                                                           ctx.grasp_pitch(object_id)))
        check_pose(stage, f"staging pose for slot {slot_index}")
    except (ValueError, WorkspaceError) as e:
        raise PlanningError(f"{what}: {e}") from None
    return CarryGoal(what, slot_index, slot, lift, stage, place)


def plan_carry(ctx: PlanningContext, object_id: str, removed: frozenset[str], goal: CarryGoal, q_start: object,
               placed: Placed | None = None) -> list[Segment]:
    """From the grasp q_start: lift, out of the shelf, down to the slot of `goal`, release ('open'), and retreat
    to the staging pose (the module docstring); `placed` (default placed_default) on the bottom shelf. Raises
    PlanningError naming the stage that failed."""
    q_start = check_q(q_start)
    p = ctx.params
    deadline = time.perf_counter() + p.carry_timeout
    stats = QueryStats()
    b = ctx.scenario.object(object_id)
    placed = ctx.placed_default(removed, goal.slot_index) if placed is None else list(placed)
    obs = ctx.collision_scene(placed).obstacles(removed | {object_id})
    support = {CARRIED: frozenset(["board:top_shelf"])}  # the one board the bottle may touch: on the lift
    if b.lying:  # and the hand of a grasp of a lying one, FINGER_FLOOR above it (context.grasp_skip)
        support |= {n: frozenset(["board:top_shelf"]) for n, v in ctx.grasp_skip(b.id).items()
                    if "board:top_shelf" in v}
    along = ctx.along_axis(object_id)  # held along its axis: carried and placed lying, as a side grasp's (x, y, z, yaw)
    carried, arm_start, arm_c = carried_models(ctx, b, q_start, obs, support)
    ctx.kin.update(q_start, jacobians=False)
    rot, pos = ctx.kin.tool_pose()
    start = np.array([*pos, *tool_angles(rot)]) if b.lying and not along else \
        np.array([*pos, math.atan2(rot[1, 2], rot[0, 2])])
    lifted = start.copy()
    lifted[2] += goal.lift
    bound = arm_start.specs[-1].clearance
    hand_c = carried_hand(ctx, carried, lifted, obs, p.carried_clearance if bound is None else bound)
    # 1. lift straight up: the only leg where the bottle may touch a board, the one it stands on
    # a bottle grasped from above: each leg starts at rest within carry_accel (its first step corrected the tool's
    # residual 0.03 rad at 0.4 rad/s at once: in the simulator the fingers kicked the bottle 4 mm in the hand)
    rest = b.lying
    up = ctx.track(q_start, [start, lifted], obs, deadline, stats, skip=support, arm=arm_start,
                   speed=p.stpik.approach_speed, ramp=p.carry_ramp, accel=p.carry_accel, from_rest=rest)
    if not up.ok:
        raise PlanningError(f"{goal.what}: lift: {up.reason}")
    # 2. out of the shelf at that height, to the staging pose, in to the slot at the release height
    # the bottle and the finger tips in front of the shelf by the arm's clearance (+ activation) before going down
    out = np.array(exit_pose(ctx.scenario, object_id, lifted,
                             max(p.hand_margin, p.stpik.clearance + p.stpik.act) + 0.002))
    rng = ctx.question_rng("carry", object_id, removed, goal.slot_index, q_start, ctx.placed_key(placed))
    # a bottle grasped from above is stood up in front of the shelf (grasp.stand_up_pose), then carried as held
    direct = [lifted, out, *map(np.array, stand_up_poses(out)), goal.stage] if b.lying and not along else \
        [lifted, out, goal.stage]
    carry = carry_legs(ctx, up.q[-1], direct, goal.place, obs, (arm_start, arm_c, hand_c), deadline, stats,
                       goal.what, rng, rest)
    back = retreat(ctx, object_id, removed, placed, goal, carry[1].q[-1], stats)
    moving = Trajectory.from_steps(up.q, up.qdot, up.dt, "lift").then(
        Trajectory.from_steps(carry[0].q, carry[0].qdot, carry[0].dt, "carry")).then(
        Trajectory.from_steps(carry[1].q, carry[1].qdot, carry[1].dt, "place"))
    return [Segment("carry", moving.resample(), "open"),
            Segment("retreat", Trajectory.from_steps(back.q, back.qdot, back.dt, "retreat").resample(), None)]


def carry_legs(ctx: PlanningContext, q_lifted: np.ndarray, direct: list[np.ndarray], place: np.ndarray,
               obs: ObstacleSet, carried: tuple[ArmGeometry, ArmGeometry, HandProxy], deadline: float,
               stats: QueryStats, what: str, rng: np.random.Generator | None = None,
               from_rest: bool = False) -> tuple[StpikResult, StpikResult]:
    """plan_carry's legs 2-3 with the bottle held (`carried`: its ArmGeometry out of the shelf and in to the
    slot, and its HandProxy): from the lifted
    pose out of the shelf to the staging pose (the `direct` poses lifted, out, stage first, then RRT-Connect;
    up to max_attempts; a bottle grasped from above: lifted, out, stood up, stage, RRT-Connect from where it stood
    up), then in to the slot at `place`. (out leg, in leg) of STPIK; PlanningError naming the
    last leg that failed."""
    p = ctx.params
    arm_out, arm_c, hand_c = carried
    fixed = direct[:-2] if len(direct) > 3 else []  # a grasp from above: out of the shelf and stood up first
    lifted, stage = direct[len(fixed)], direct[-1]
    last = "no Cartesian path out of the shelf"
    mid: list[np.ndarray] | None
    for attempt in range(p.max_attempts):
        if attempt == 0 and p.direct_first and hand_c.path_clear(direct, obs, p.resolution):
            stats.direct_paths += 1
            mid = direct
        else:
            t = time.perf_counter()
            mid = ctx.rrt.plan(lifted[:4], stage[:4],
                               lambda s_: not hand_c.collides(*pose_matrix((*s_, pose_pitch(stage))), obs),
                               4 * p.rrt_max_checks, deadline, draw_seed(rng))
            stats.rrt_time += time.perf_counter() - t
            stats.rrt_calls += 1
            if mid is None:
                continue
            if fixed:  # RRT-Connect at the stood-up bottle's pitch
                mid = fixed + [np.array([*m, stage[4]]) for m in mid]
        r = ctx.track(q_lifted, mid, obs, deadline, stats, arm=arm_out, ramp=p.carry_ramp, accel=p.carry_accel,
                      from_rest=from_rest)
        if not r.ok:
            last = f"out of the shelf: {r.reason}"
            continue
        # in to the slot at approach speed: 10 mm above and below the bottle in the shipped shelf's bottom
        # compartment, and the clearance tasks must not freeze it at the front edge
        r2 = ctx.track(r.q[-1], [stage, place], obs, deadline, stats, arm=arm_c, speed=p.stpik.approach_speed,
                       ramp=p.carry_ramp, accel=p.carry_accel, from_rest=from_rest)
        if r2.ok:
            return r, r2
        last = f"in to the slot: {r2.reason}"
    raise PlanningError(f"{what}: {last}")


def retreat(ctx: PlanningContext, object_id: str, removed: frozenset[str], placed: Placed, goal: CarryGoal,
            q_placed: np.ndarray, stats: QueryStats) -> StpikResult:
    """Straight back from the place pose to the staging pose, the bottle now placed in its slot (the hand may touch
    it); PlanningError if STPIK rejects it."""
    p = ctx.params
    obs = ctx.collision_scene(placed + [(object_id, goal.slot)]).obstacles(removed | {object_id})
    skip = {n: frozenset([f"placed:{object_id}"]) for n in HAND_PARTS}
    back = ctx.track(q_placed, [goal.place, goal.stage], obs, time.perf_counter() + p.carry_timeout, stats,
                     skip=skip, ramp=p.carry_ramp)
    if not back.ok:
        raise PlanningError(f"retreat after placing {object_id!r}: {back.reason}")
    return back


def carried_shape(b: ShelfObject, grasp_yaw: float, clearance: float, tilt: float, along: bool = False
                  ) -> CapsuleSpec:
    """The object held at its real size, with its clearance bound: collision.carried_bottle (a bottle grasped from
    above too: its axis along tool y, `held_standoff` beyond the tool), or carried_box for a
    box held by the face nearest to square to the tool's yaw `grasp_yaw` at the grasp (grasp.grasp_extent), turned
    by the yaw error the grasp accepted (stpik.grasp_yaw_tol). `along`: a lying cylinder grasped along its axis
    (grasp.grasp_along_axis): its axis along tool z, `along_axis_standoff` beyond the tool and `along_axis_raise`
    below it (-tool y: the hand is horizontal)."""
    if along:
        z, half, low = rd.D67 + along_axis_standoff(b), b.height / 2, -along_axis_raise(b)
        return capsule_spec(CARRIED, rd.LINK_NAMES[6], (0, low, z - half), (0, low, z + half), b.radius,
                            cylinder=True, clearance=clearance)
    half_depth, width = grasp_extent(b, grasp_yaw)
    if b.shape == "box":
        face = min(face_yaws(b), key=lambda y: abs(math.remainder(y - grasp_yaw, 2 * math.pi)))
        turn = math.remainder(face - grasp_yaw, 2 * math.pi)
        return carried_box(2 * half_depth, width, b.height, grasp_standoff(half_depth), turn, clearance)
    return carried_bottle(b.radius, b.height, held_standoff(b, grasp_yaw), clearance, tilt)


def carried_models(ctx: PlanningContext, b: ShelfObject, q_start: np.ndarray, obs: ObstacleSet,
                   support: dict[str, frozenset[str]]) -> tuple[CapsuleSpec, ArmGeometry, ArmGeometry]:
    """(carried bottle, arm holding it out of the shelf, arm holding it in to the slot), the object held as the
    tool took it at q_start (`carried_shape` at the tool's yaw there). The bottle is modelled on the hand where
    the tool stopped at the grasp (STPIK's final tolerance, up to 4 mm from the bottle's
    perceived place); where that model stands closer to a neighbour than `carried_clearance`, the lift and
    the way out keep that start distance less START_RELIEF (less half of it under 2 x START_RELIEF: the bound
    never allows contact) as the bound, whatever it is (a model in contact within the perception and STPIK
    tolerances included): lifted straight up and then drawn back, the bottle
    may never come closer to anything than it already stood, and STPIK checks that it does not. Otherwise the
    start would fail the bound at once and the pick would be refused for the model's offset. A model that
    penetrates a neighbour at the start (no distance to keep) keeps the full bound: refused."""
    p = ctx.params
    grasp_yaw = ctx.grasp_yaw(q_start)
    tilt = held_tilt(ctx.grasp_pitch(b.id)) if b.lying else 0.0
    along = ctx.along_axis(b.id)
    carried = carried_shape(b, grasp_yaw, p.carried_clearance, tilt, along)
    arm_c = ArmGeometry(ctx.kin, [carried])
    ctx.kin.update(q_start, jacobians=False)
    arm_c.pose()
    near = [d for i, _, d, _, _ in arm_c.obstacle_distances(obs, p.carried_clearance, support)
            if arm_c.specs[i].name == CARRIED]
    gap = min(near, default=math.inf)
    if gap >= p.carried_clearance or gap == PENETRATION:
        return carried, arm_c, arm_c
    start = carried_shape(b, grasp_yaw, gap - min(START_RELIEF, gap / 2), tilt, along)
    return carried, ArmGeometry(ctx.kin, [start]), arm_c


def carried_hand(ctx: PlanningContext, carried: CapsuleSpec, lifted: Pose, obs: ObstacleSet,
                 floor: float) -> HandProxy:
    """The Cartesian planner's hand proxy holding the bottle, inflated by its clearance bound plus STPIK's
    activation band, or less where the lifted start is closer than that to a neighbour (in steps of
    START_RELIEF, down to `floor`, the bound STPIK keeps on the way out): a start inside the inflation left
    RRT-Connect and the direct path no valid start ("no Cartesian path out of the shelf") although the
    bottle then moves away."""
    p = ctx.params
    full = p.carried_clearance + p.stpik.act
    for m in np.arange(full, floor - 1e-9, -START_RELIEF):
        hand = HandProxy(p.hand_margin, [carried], attached_margin=float(m))
        if not hand.collides(*pose_matrix(lifted), obs):
            return hand
    return HandProxy(p.hand_margin, [carried], attached_margin=full)
