"""The feasibility question of the Q-Tree answered by the motion planner (paper Sect. 4.1 and Eq. 11), and the pick.

feasibility(i, removed): 1) action to pose: side grasp and pre-grasp of object i for a few approach yaws
(`candidates`: those whose pre-grasp and approach the hand proxy finds clear); 2) RRT-Connect (OMPL) in Cartesian
space for the tool from its home pose to the pre-grasp, keeping the hand clear of the bottles still there
(`cartesian_path`, the direct path first); then the straight approach to the grasp; 3) STPIK check (Eq. 9-10)
tracking that path; a rejected path is re-sampled up to max_attempts times (`pick_lanes`); when certifying (a certify
request, an execution's pick, or every answer with certify_relocation) the rest of the relocation must plan from the
grasp (certify.py). 4) label g_U / g_O / g_T, planning time, attempts and the joint trajectory (100 Hz, Q convention,
within Table 7); an uncertified feasible answer names the objects its motion comes near (context.near_objects); a
feasible one names its action, the pick the object's pose takes (relocation_common.feasibility.pick_action:
side_grasp standing, top_grasp lying flat).

Budgets are work, not time: validity checks per RRT-Connect attempt (rrt_max_checks), IK steps per STPIK check
(stpik.step_budget), attempts per query (max_attempts); so a question gets the same answer on an idle and on a
loaded machine. `timeout` / `carry_timeout` are wall-clock safety nets only: reached first, the query raises
SafetyNetTimeout (no answer; never g_U, so no cache keeps it).
"""
from __future__ import annotations

import math
import time
from typing import Iterable

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import FeasibilityAnswer, Label, pick_action
from stpik_motion_planner.model.approach import squeezed_approach
from stpik_motion_planner.model.blockers import answer_blockers
from stpik_motion_planner.model.collision import HandProxy, ObstacleSet
from stpik_motion_planner.model.grasp import Grasp, Pose, WorkspaceError, pose_matrix, pose_pitch, side_grasp
from stpik_motion_planner.planning.certify import certify as certify_rest
from stpik_motion_planner.planning.context import PlanningContext, draw_seed, near_objects
from stpik_motion_planner.planning.results import PlanningError, QueryStats, Segment
from stpik_motion_planner.planning.trajectory import Trajectory

Picked = tuple[Trajectory | None, int, str]  # (trajectory or None, attempts, message)


def feasibility(ctx: PlanningContext, object_id: str, removed: Iterable[str] = frozenset(),
                timeout: float | None = None, certify: bool = False) -> FeasibilityAnswer:
    """g_T / g_O with the home -> pre-grasp -> grasp trajectory (100 Hz) and its action (side_grasp or top_grasp) if a
    path passes the STPIK check (and, with `certify` or certify_relocation, the rest of its relocation plans), g_U
    otherwise. Raises UnknownObjectError /
    ValueError / WorkspaceError on bad input, SafetyNetTimeout when the wall-clock `timeout` (default params.timeout)
    ran out before the work budget (no answer)."""
    t0 = time.perf_counter()
    removed = ctx.check_question(object_id, removed)
    if timeout is not None and not (isinstance(timeout, (int, float)) and math.isfinite(timeout)):
        raise ValueError(f"timeout must be a finite number of seconds, got {timeout!r}")
    budget = ctx.params.timeout if timeout is None or timeout <= 0 else float(timeout)
    deadline = t0 + budget
    stats = QueryStats()
    ctx.last_stats = stats
    ok_label = Label.TARGET if object_id == ctx.scenario.target_id else Label.OBSTACLE
    certify = certify or ctx.params.certify_relocation
    traj, attempts, msg = pick(ctx, object_id, removed, deadline, stats, certify)
    dt = time.perf_counter() - t0
    if traj is None:  # with the lane blockers of the refused pick (docs/motion_planner.md, "Blockers")
        return FeasibilityAnswer(Label.UNFEASIBLE, dt, attempts, msg,
                                 blockers=answer_blockers(ctx, object_id, removed))
    return FeasibilityAnswer(ok_label, dt, attempts, msg, traj, near=ctx.pick_near.get((object_id, removed)),
                             action=pick_action(ctx.scenario.object(object_id).lying))


def plan_pick(ctx: PlanningContext, object_id: str, removed: Iterable[str] = frozenset()) -> list[Segment]:
    """Home -> pre-grasp -> grasp, then close the gripper: the certified pick (the lane a certify request accepts).
    Raises PlanningError if unfeasible."""
    removed = ctx.check_question(object_id, removed)
    traj, _, msg = pick(ctx, object_id, removed, time.perf_counter() + ctx.params.carry_timeout, QueryStats(), True)
    if traj is None:
        raise PlanningError(f"pick of {object_id!r}: {msg}")
    return [Segment("pick", traj, "close")]


def pick(ctx: PlanningContext, object_id: str, removed: frozenset[str], deadline: float, stats: QueryStats,
         certify: bool) -> Picked:
    """Home -> pre-grasp -> grasp for the yaws of the first tier; if none gave one, for the second
    (yaw_tiers): (trajectory or None, attempts, message). A lying or gone bottle: none (not_graspable).
    `certify`: a lane counts only if the rest of its relocation plans (certify.py)."""
    why = ctx.not_graspable(object_id)
    if why:
        return None, 0, why
    try:
        ctx.carry_heights(object_id)
    except WorkspaceError as e:  # it could be grasped but not carried away: not a relocation
        return None, 0, str(e)
    obs = ctx.scene.obstacles(removed)
    attempts, last = 0, ""
    for tier, yaws in enumerate(ctx.yaw_tiers(object_id)):
        cands = candidates(ctx, object_id, obs, yaws)
        if not cands:
            continue
        # the first tier's draws are those of a planner without the second (context.UNSEEDED)
        rng = ctx.question_rng("pick", object_id, removed, *(["wide"] if tier else []))
        budget = ctx.params.max_attempts if tier == 0 else max(ctx.params.max_attempts, len(cands))
        traj, n, last = pick_lanes(ctx, object_id, removed, obs, cands, budget, rng, deadline, stats, certify)
        attempts += n
        if traj is not None:
            return traj, attempts, last
    if not attempts:
        return None, 0, "no collision-free pre-grasp and approach for any yaw"
    return None, attempts, f"{attempts} attempts failed; last: {last}"


def pick_lanes(ctx: PlanningContext, object_id: str, removed: frozenset[str], obs: ObstacleSet, cands: list[Grasp],
               budget: int, rng: np.random.Generator | None, deadline: float, stats: QueryStats, certify: bool
               ) -> Picked:
    """Up to `budget` sampled paths over the grasps `cands` in turn (each one's direct path first):
    (trajectory or None, attempts, the grasp used or the last failure). The grasp configuration goes to
    ctx.pick_end; uncertified, the objects the motion comes near to ctx.pick_near (context.near_objects)."""
    p = ctx.params
    skip = ctx.grasp_skip(object_id)
    attempts, last = 0, ""
    while attempts < budget:
        g = cands[attempts % len(cands)]
        first = attempts < len(cands)
        attempts += 1
        why = squeezed_approach(g, obs, skip, p.stpik.clearance + p.stpik.act, p.resolution, p.stpik.final_tol_pos)
        if why:  # the draws of its path taken all the same: every later attempt draws as before (model/approach.py)
            cartesian_path(ctx, ctx.home, g.pre_grasp, obs, ctx.hand, 0, deadline, stats, first, rng, plan=False)
            last = why
            continue
        path = cartesian_path(ctx, ctx.home, g.pre_grasp, obs, ctx.hand, p.rrt_max_checks, deadline, stats, first,
                              rng)
        if path is None:
            last = f"no Cartesian path to the pre-grasp (yaw {g.yaw:+.2f})"
            continue
        r1 = ctx.track(rd.Q_HOME, path, obs, deadline, stats)
        if not r1.ok:
            last = f"STPIK rejected the path to the pre-grasp: {r1.reason}"
            continue
        r2 = ctx.track(r1.q[-1], [np.array(g.pre_grasp), np.array(g.grasp)], obs, deadline, stats, skip,
                       speed=p.stpik.approach_speed, yaw_tol=p.stpik.grasp_yaw_tol)
        if not r2.ok:
            last = f"STPIK rejected the approach: {r2.reason}"
            continue
        if certify:
            why = certify_rest(ctx, object_id, removed, r2.q[-1])
            if why:
                last = f"the rest of the relocation: {why}"
                continue
        traj = Trajectory.from_steps(r1.q, r1.qdot, r1.dt, "to_pre_grasp").then(
            Trajectory.from_steps(r2.q, r2.qdot, r2.dt, "approach")).resample()
        ctx.pick_end[(object_id, removed)] = r2.q[-1]
        ctx.pick_near[(object_id, removed)] = None if certify else near_objects(
            ctx, object_id, [*r1.q, *r2.q], [*path, np.asarray(g.grasp)])
        return traj, attempts, f"yaw {g.yaw:+.2f}, {len(path)} waypoints"
    return None, attempts, last


def candidates(ctx: PlanningContext, object_id: str, obs: ObstacleSet, yaws: list[float] | None = None
               ) -> list[Grasp]:
    """Grasps (of `yaws`, default every tier's) whose pre-grasp and straight approach are clear for the hand
    (the target excluded for the palm and fingers on the approach only)."""
    skip = ctx.grasp_skip(object_id)
    out = []
    for yaw in ctx.all_yaws(object_id) if yaws is None else yaws:
        try:
            g = side_grasp(ctx.scenario, object_id, yaw, ctx.params.pre_grasp_distance, ctx.ceiling_clearance)
        except WorkspaceError:
            if yaw == 0.0:
                raise
            continue
        if not ctx.rrt.contains(g.pre_grasp[:4 if len(g.pre_grasp) < 5 else 3]):  # from above: any yaw (direct)
            continue
        if ctx.hand.collides(*pose_matrix(g.pre_grasp), obs):
            continue
        if ctx.hand.path_clear([g.pre_grasp, g.grasp], obs, ctx.params.resolution, skip):
            out.append(g)
    return out


def front_of_shelf(ctx: PlanningContext, pose: Pose) -> np.ndarray:
    """In front of the shelf at the height and lateral position of `pose` (the start of a direct entry): on the
    line of its approach, or straight in (along x) for a grasp from above, whose approach comes down."""
    x = min(pose[0], ctx.scenario.shelf.x_front - 0.06)
    if len(pose) == 5 or len(pose) > 5 and pose[4]:
        return np.array([x, *pose[1:]])
    return np.array([x, pose[1] - (pose[0] - x) * math.tan(pose[3]), pose[2], *pose[3:]])


def cartesian_path(ctx: PlanningContext, start: Pose, goal: Pose, obs: ObstacleSet,
                   hand: HandProxy, max_checks: int, deadline: float, stats: QueryStats, first: bool,
                   rng: np.random.Generator | None = None, plan: bool = True) -> list[np.ndarray] | None:
    """First attempt: the direct path start -> stage in front of the shelf -> goal, if clear; otherwise and on
    later attempts RRT-Connect. A goal from above (its pitch: grasp.tool_rotation) is reached tilted from the start
    on: the hand tilts at the start, and RRT-Connect plans (x, y, z, yaw) at that pitch. A goal with a roll (a push's
    rolled hand) is planned at that roll, from a start with the same roll. `plan` False: only the
    draws from `rng` that planning would take (a skipped lane), None."""
    pitch = pose_pitch(goal)
    if pitch:
        start = np.array([*start[:4], 0.0]) if len(start) < 5 else np.asarray(start, float)
    if first and ctx.params.direct_first:
        direct = [np.asarray(start, float), front_of_shelf(ctx, goal), np.asarray(goal, float)]
        if hand.path_clear(direct, obs, ctx.params.resolution):
            stats.direct_paths += plan
            return direct if plan else None
    if not ctx.rrt.contains(goal[:4]):  # a grasp from above turned beyond the planner's yaws: the direct path only
        return None
    seed = draw_seed(rng)
    if not plan:
        return None
    t = time.perf_counter()
    rest = tuple(float(a) for a in goal[4:]) or (pitch,)  # (pitch[, roll]) kept along the path
    path = ctx.rrt.plan(start[:4], goal[:4], lambda s: not hand.collides(*pose_matrix((*s, *rest)), obs), max_checks,
                        deadline, seed)
    stats.rrt_time += time.perf_counter() - t
    stats.rrt_calls += 1
    if pitch and path is not None:
        path = [np.asarray(start, float)] + [np.array([*s, *rest]) for s in path]
    elif len(goal) > 5 and path is not None:
        path = [np.array([*s, *rest]) for s in path]
    return path
