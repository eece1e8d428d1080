"""A feasible pick certified for its whole relocation (docs/motion_planner.md, "Lazy certification"): from the
grasp, the carry to the next slot, the retreat and the way home must plan too, or the pick lane is not taken. Asked
for every answer with certify_relocation (eager), else by a certify request (MotionPlanner.certify) and by the pick
of an execution (plan_pick). Kept by grasp: (object, removed set, joint configuration at the grasp) -> verdict, so a
certification asked again (a second question, the execution's pick) plans nothing."""
from __future__ import annotations

import numpy as np

from stpik_motion_planner.model.grasp import WorkspaceError
from stpik_motion_planner.planning.carry import carry_goal, plan_carry
from stpik_motion_planner.planning.context import PlanningContext
from stpik_motion_planner.planning.home import plan_home
from stpik_motion_planner.planning.results import PlanningError


def certify(ctx: PlanningContext, object_id: str, removed: frozenset[str], q_grasp: np.ndarray) -> str:
    """'' if the rest of the relocation from the grasp q_grasp plans (carry to slot len(removed) with the removed
    bottles in the earlier slots, retreat, way home), else why not. `removed`: the question's, already checked."""
    key = (object_id, removed, np.round(np.asarray(q_grasp, float), 9).tobytes())
    why = ctx.certified.get(key)
    if why is None:
        why = ctx.certified[key] = _plan_rest(ctx, object_id, removed, q_grasp)
    return why


def _plan_rest(ctx: PlanningContext, object_id: str, removed: frozenset[str], q_grasp: np.ndarray) -> str:
    """certify's planning (no memo): '' or the failure."""
    k = len(removed)
    try:
        placed = ctx.placed_default(removed, k)
        goal = carry_goal(ctx, object_id, k, ctx.grasp_yaw(q_grasp))
        _, retreat = plan_carry(ctx, object_id, removed, goal, q_grasp, placed)
        plan_home(ctx, retreat.trajectory.positions[-1], removed | {object_id},
                  placed + [(object_id, ctx.scenario.slot(k))])
    except (PlanningError, WorkspaceError, ValueError) as e:
        return str(e)
    return ""
