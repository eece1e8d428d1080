"""One push on a real or simulated arm (ROS-free): what a RelocateObject goal with action "push" carries out.

plan the push (planning/push/: home -> contact -> push -> retreat -> home) -> [the way home first, if the arm is
away from it] -> shut the gripper (closed on nothing) -> approach -> push -> retreat -> home -> open the gripper.
Nothing moves before the whole push is planned. After a failure or a cancel, `recover_push` goes back along the
motions made, newest first (the same paths; back along the push the hand leaves the object where it is), and opens
the gripper at home. The arm is any relocation.Arm; the progress is reported with relocation.PUSH_PHASES.
"""
from __future__ import annotations

import math
from contextlib import nullcontext
from typing import Callable, ContextManager, Mapping

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.scenario import Shelf
from stpik_motion_planner.execution.goal_check import SeenBottle, on_top_shelf
from stpik_motion_planner.execution.relocation import Arm, Progress
from stpik_motion_planner.planning.params import node_parameters
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.push import PushPlan
from stpik_motion_planner.planning.results import PlanningError

PHASE = {"approach": "approach_push", "push": "push", "retreat": "retreat_push", "home": "home_push"}


def plan(planner: MotionPlanner, object_id: str, clear_for: str, removed: list[str]) -> PushPlan:
    """The push of `object_id` out of the lanes of `clear_for` (planner.push_feasibility, the carry's safety net);
    PlanningError with the reason when there is none."""
    ans, got = planner.push_feasibility(object_id, clear_for, removed, planner.params.carry_timeout)
    if got is None:
        raise PlanningError(f"push of {object_id!r}: {ans.message}")
    return got


def push(planner: MotionPlanner, arm: Arm, object_id: str, clear_for: str, removed: list[str],
         home_tol: float | None = None, lock: ContextManager[object] | None = None,
         progress: Progress | None = None, on_change: Callable[[], None] = lambda: None) -> PushPlan:
    """Push `object_id` out of the lanes of `clear_for` (the module docstring); `lock`, `progress`, `on_change`,
    `home_tol` as relocation.relocate. The plan made before moving; PlanningError or the arm's error on failure."""
    lock = lock if lock is not None else nullcontext()
    home_tol = float(node_parameters()["home_tol"]) if home_tol is None else home_tol
    arm.phase("plan_push")
    with lock:
        made = plan(planner, object_id, clear_for, list(removed))
    progress = progress if progress is not None else Progress()
    progress.object_id, progress.removed = object_id, list(removed)
    q = arm.measured()
    if float(np.max(np.abs(q - rd.Q_HOME))) > home_tol:
        with lock:
            home = planner.plan_home(q, removed)
        arm.follow(home, "home_push")  # not recorded: a recovery does not go back along it
    arm.gripper("shut", "shut")
    for seg in made.segments:
        _follow(arm, progress, on_change, seg.trajectory, PHASE[seg.name])
    arm.gripper("open", "open")
    arm.phase("pushed")
    return made


def _follow(arm: Arm, progress: Progress, on_change: Callable[[], None], traj: object, phase: str) -> None:
    progress.moves.append((phase, traj))
    on_change()
    arm.follow(traj, phase)  # type: ignore[arg-type]


def recover_push(arm: Arm, progress: Progress, on_change: Callable[[], None] = lambda: None) -> str:
    """A safe state after a failed or cancelled push: back along the motions made, newest first, then the gripper
    opened (the arm home, nothing held). What was done; raises (the arm's error) if it could not."""
    if not progress.moves:
        return "arm stopped (it had not moved towards the object)"
    for _, traj in reversed(list(progress.moves)):
        arm.follow(traj.back_from(arm.measured()), "recover_push")
        progress.moves = [m for m in progress.moves if m[1] is not traj]
        on_change()
    arm.gripper("open", "recover_push")
    return f"arm back home along the push of {progress.object_id}, gripper open"


def push_problems(shelf: Shelf, before: Mapping[str, SeenBottle], after: Mapping[str, SeenBottle], made: PushPlan,
                  tolerance: float, end_tolerance: float) -> list[str]:
    """What is wrong after the push `made` (empty: it did what it predicted): the pushed object (when `after` shows
    it) off the top shelf or farther than `end_tolerance` (m, on the board) from its predicted end pose; any other
    object in both scenes moved more than `tolerance` (m, 3D)."""
    problems = []
    b = after.get(made.object_id)
    if b is not None:
        off = math.dist((b.x, b.y), made.end[:2])
        if not on_top_shelf(shelf, b) or abs(b.z - made.end[2]) > tolerance:
            problems.append(f"{made.object_id} is no longer standing on the top shelf")
        elif off > end_tolerance:
            problems.append(f"{made.object_id} is {off * 1000:.0f} mm from its predicted end pose "
                            f"({made.end[0]:.3f}, {made.end[1]:.3f})")
    for i in sorted(set(before) & set(after) - {made.object_id}):
        p, q = before[i], after[i]
        d = math.dist((p.x, p.y, p.z), (q.x, q.y, q.z))
        if d > tolerance:
            problems.append(f"{i} moved {d * 1000:.0f} mm")
    return problems
