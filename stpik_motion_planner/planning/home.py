"""The way home (paper Sect. 4.1, the end of a relocation): from the staging pose where a retreat ends, back along
the staging pose's reference track without sampling; from anywhere else, RRT-Connect in joint space with the same
collision checker as STPIK (the scene's clearance), timed within Table 7.
"""
from __future__ import annotations

import math
import time
from typing import Iterable, Sequence

import numpy as np

from relocation_common import robot_description as rd
from stpik_motion_planner.model.collision import PENETRATION, ArmGeometry, ObstacleSet
from stpik_motion_planner.model.grasp import WorkspaceError, place_poses
from stpik_motion_planner.planning.context import Placed, PlanningContext, check_q, draw_seed
from stpik_motion_planner.planning.results import PlanningError, QueryStats
from stpik_motion_planner.planning.rrt import JointRRT
from stpik_motion_planner.planning.trajectory import Trajectory


def plan_home(ctx: PlanningContext, q_from: object, removed: Iterable[str] = frozenset(),
              placed: Placed | None = None) -> Trajectory:
    """From q_from back to Q_HOME: via the staging pose's reference track when q_from is where a retreat ends,
    else joint-space RRT-Connect with the scene's clearance. PlanningError if neither finds a way."""
    removed = ctx.scenario.check_ids(removed)
    placed = ctx.placed_default(removed, -1) if placed is None else list(placed)
    obs = ctx.collision_scene(placed).obstacles(removed)
    via = home_via_stage(ctx, check_q(q_from), obs, placed)
    if via is not None:
        return time_joint_path(via, 0.9 * rd.QDOT_MAX, ctx.params.stpik.dt).resample()
    rng = ctx.question_rng("home", np.asarray(q_from, float), removed, ctx.placed_key(placed))
    traj = plan_joint(ctx, q_from, rd.Q_HOME, obs, 4 * ctx.params.rrt_max_checks,
                      time.perf_counter() + ctx.params.carry_timeout, rng=rng)
    if traj is None:
        raise PlanningError("no collision-free joint path back to the home configuration")
    return traj.resample()


def home_via_stage(ctx: PlanningContext, q_from: np.ndarray, obs: ObstacleSet, placed: Placed
                   ) -> list[np.ndarray] | None:
    """The way home from the staging pose in front of a placed bottle's slot (where every retreat ends) without
    sampling: the straight joint motion to that pose's reference configuration, then the reference track
    reversed (`stage_reference`); None if q_from is at no such pose or that motion is not clear (with the
    home planner's 5 mm margin)."""
    p = ctx.params
    ctx.kin.update(q_from, jacobians=False)
    rot, pos = ctx.kin.tool_pose()
    for oid, xy in placed:
        try:
            _, release = ctx.carry_heights(oid)
            # the staging pose: the same whichever face of a box the hand holds (grasp yaw 0 for any)
            stage = np.array(place_poses(ctx.scenario, oid, xy, release, p.stage_distance, 0.0,
                                         ctx.grasp_pitch(oid))[0])
        except WorkspaceError:
            continue
        if np.linalg.norm(pos - stage[:3]) > 2 * p.stpik.final_tol_pos or \
                abs(math.atan2(rot[1, 2], rot[0, 2]) - stage[3]) > 2 * p.stpik.final_tol_ori:
            continue
        ref = stage_reference(ctx, stage, placed)
        if ref is None or not joint_motion_clear(ctx, q_from, ref[-1], obs):
            return None
        return [q_from] + ref[::-1]
    return None


def stage_reference(ctx: PlanningContext, stage: np.ndarray, placed: Placed) -> list[np.ndarray] | None:
    """STPIK's track of the straight tool path from home to the staging pose `stage` with every bottle of the
    top shelf present and `placed` on the bottom one (None if rejected): clear for any removed set, so one per
    (staging pose, bottom shelf's geometry); a function of those only (cached: it is no history)."""
    key = (tuple(np.round(stage, 6)), ctx.placed_key(placed))
    if key not in ctx.stage_refs:
        obs = ctx.collision_scene(placed).obstacles(frozenset())
        home = ctx.home if len(stage) < 5 else np.array([*ctx.home, 0.0])  # a stage tilted up (grasp.place_poses)
        r = ctx.track(rd.Q_HOME, [home, stage], obs, time.perf_counter() + ctx.params.carry_timeout,
                      QueryStats())
        ctx.stage_refs[key] = list(r.q) if r.ok else None
    return ctx.stage_refs[key]


def joint_motion_clear(ctx: PlanningContext, a: np.ndarray, b: np.ndarray, obs: ObstacleSet,
                       margin: float = 0.005, arm: ArmGeometry | None = None) -> bool:
    """The straight joint motion a -> b valid (joint_valid; `arm` its) every joint_resolution."""
    n = max(1, int(math.ceil(float(np.max(np.abs(b - a))) / ctx.params.joint_resolution)))
    return all(joint_valid(ctx, a + (b - a) * (k / n), obs, arm, margin) for k in range(1, n + 1))


def joint_valid(ctx: PlanningContext, q: np.ndarray, obs: ObstacleSet, arm: ArmGeometry | None = None,
                margin: float = 0.0) -> bool:
    """Joint-space validity with the same collision checker: limits, self-collision, clearance."""
    arm = arm or ctx.arm
    p = ctx.params.stpik
    if np.any(q < rd.Q_LOWER + p.joint_margin) or np.any(q > rd.Q_UPPER - p.joint_margin):
        return False
    ctx.kin.update(q, jacobians=False)
    arm.pose()
    if arm.self_distances(p.self_clearance + margin):
        return False
    for _, _, d, _, _ in arm.obstacle_distances(obs, p.clearance + margin):
        if d == PENETRATION or d < p.clearance + margin:
            return False
    return True


def plan_joint(ctx: PlanningContext, q_from: object, q_to: object, obs: ObstacleSet, max_checks: int,
               deadline: float, margin: float = 0.005, rng: np.random.Generator | None = None,
               arm: ArmGeometry | None = None) -> Trajectory | None:
    """RRT-Connect in joint space (same collision checker; `arm`: joint_valid's), timed within Table 7 at 90 %;
    `rng`: the question's generator (question_rng), None for OMPL's."""
    q_from, q_to = check_q(q_from), check_q(q_to)
    lo = np.maximum(rd.Q_LOWER, np.minimum(q_from, q_to) - math.pi)
    hi = np.minimum(rd.Q_UPPER, np.maximum(q_from, q_to) + math.pi)
    rrt = JointRRT(lo, hi, ctx.params.joint_resolution, ctx.params.simplify_checks)
    path = rrt.plan(q_from, q_to, lambda q: joint_valid(ctx, q, obs, arm, margin), max_checks, deadline,
                    draw_seed(rng))
    if path is None:
        return None
    return time_joint_path(path, 0.9 * rd.QDOT_MAX, ctx.params.stpik.dt)


def time_joint_path(path: Sequence[np.ndarray], vmax: np.ndarray, dt: float) -> Trajectory:
    """Straight joint segments at constant velocity, each scaled so every joint stays within vmax; steps of dt."""
    qs, qdots = [np.asarray(path[0], float)], []
    for a, b in zip(path[:-1], path[1:]):
        d = np.asarray(b) - np.asarray(a)
        n = max(1, int(math.ceil(float(np.max(np.abs(d) / vmax)) / dt)))
        for _ in range(n):
            qdots.append(d / (n * dt))
            qs.append(qs[-1] + d / n)
    return Trajectory.from_steps(np.array(qs), np.array(qdots), dt, "joint")
