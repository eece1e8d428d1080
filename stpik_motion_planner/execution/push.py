"""One push on a real or simulated arm (ROS-free): what a RelocateObject goal with action "push" carries out.

plan the push (planning/push/: home -> contact -> push -> retreat -> home) -> [the way home first, if the arm is
away from it] -> shut the gripper (closed on nothing) -> approach -> push -> retreat -> home -> open the gripper.
Nothing moves before the whole push is planned. Each motion is recorded in the `Progress` (then `on_change`: the
node's journal) before it starts, the approach before the gripper shuts, so a recorded motion means shut fingers.
After a failure, a cancel, or a process that died mid-push (the journal: the plan and the motions started),
`recover_push` brings the arm home from where it is and opens the gripper: before the retreat, back along the
motions made, newest first (the same paths; back along the push the hand leaves the object where it is); once the
retreat started (the object at its end pose), on along the retreat and the way home as planned, never back into the
object. The arm is any relocation.Arm; the progress is reported with relocation.PUSH_PHASES.
"""
from __future__ import annotations

import math
from contextlib import nullcontext
from typing import Callable, ContextManager, Mapping

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.scenario import Shelf
from stpik_motion_planner.execution.follower import joint_error
from stpik_motion_planner.execution.goal_check import Point, SeenBottle, on_top_shelf
from stpik_motion_planner.execution.relocation import Arm, Progress
from stpik_motion_planner.model.push import ROLL, SLIDE
from stpik_motion_planner.planning.params import node_parameters
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.push import PushPlan
from stpik_motion_planner.planning.results import PlanningError
from stpik_motion_planner.planning.trajectory import Trajectory

PHASE = {"approach": "approach_push", "push": "push", "retreat": "retreat_push", "home": "home_push"}
AFTER_PUSH = ("retreat_push", "home_push")  # the recorded phases once the object stands at its end pose


def plan(planner: MotionPlanner, object_id: str, clear_for: str, removed: list[str]) -> PushPlan:
    """The push of `object_id` out of the lanes of `clear_for` (planner.push_feasibility, the carry's safety net);
    PlanningError with the reason when there is none."""
    ans, got = planner.push_feasibility(object_id, clear_for, removed, planner.params.carry_timeout)
    if got is None:
        raise PlanningError(f"push of {object_id!r}: {ans.message}")
    return got


def push(planner: MotionPlanner, arm: Arm, object_id: str, clear_for: str, removed: list[str],
         home_tol: float | None = None, lock: ContextManager[object] | None = None,
         progress: Progress | None = None, on_change: Callable[[], None] = lambda: None,
         on_plan: Callable[[PushPlan], None] = lambda _: None) -> PushPlan:
    """Push `object_id` out of the lanes of `clear_for` (the module docstring); `lock`, `progress`, `on_change`,
    `home_tol` as relocation.relocate; `on_plan(plan)` once the push is planned, before anything moves (the
    node's journal keeps it). The plan made before moving; PlanningError or the arm's error on failure."""
    lock = lock if lock is not None else nullcontext()
    home_tol = float(node_parameters()["home_tol"]) if home_tol is None else home_tol
    arm.phase("plan_push")
    with lock:
        made = plan(planner, object_id, clear_for, list(removed))
    on_plan(made)
    progress = progress if progress is not None else Progress()
    progress.object_id, progress.removed = object_id, list(removed)
    q = arm.measured()
    if float(np.max(np.abs(q - rd.Q_HOME))) > home_tol:
        with lock:
            home = planner.plan_home(q, removed)
        arm.follow(home, "home_push")  # not recorded: a recovery does not go back along it
    for k, seg in enumerate(made.segments):
        progress.moves.append((PHASE[seg.name], seg.trajectory))
        on_change()
        if k == 0:  # recorded first: a process that dies while the fingers shut still opens them
            arm.gripper("shut", "shut")
        arm.follow(seg.trajectory, PHASE[seg.name])
    arm.gripper("open", "open")
    arm.phase("pushed")
    return made


def recover_push(arm: Arm, progress: Progress, on_change: Callable[[], None] = lambda: None,
                 made: PushPlan | None = None, near: float | None = None) -> str:
    """A safe state after a failed, cancelled or interrupted push (the module docstring): the arm home from where it
    is, then the gripper opened (nothing held; the next grasp needs it open). Once the retreat started and the plan
    `made` is known: on along the planned motion the arm is on (its sample nearest the arm within `near` rad; None:
    config/motion_planner.yaml's recover_near) and the rest of the plan, each recorded in `progress.moves` before it
    starts (a recovery killed in turn is taken up again from there); else back along the motions made, newest first,
    each gone back along leaving `progress.moves`. on_change() after each change. What was done; raises (the arm's
    error) if it could not."""
    if not progress.moves:
        return "arm stopped (it had not moved towards the object)"
    near = float(node_parameters()["recover_near"]) if near is None else near
    on = after_push(progress, made, arm.measured(), near) if made is not None else None
    if on is not None:
        for phase, traj in on:
            progress.moves.append((phase, traj))
            on_change()
            arm.follow(traj, "recover_push")
        arm.gripper("open", "recover_push")
        return f"{progress.object_id} was pushed; arm on along its way home, gripper open"
    for _, traj in reversed(list(progress.moves)):
        arm.follow(traj.back_from(arm.measured()), "recover_push")
        progress.moves = [m for m in progress.moves if m[1] is not traj]
        on_change()
    arm.gripper("open", "recover_push")
    return f"arm back home along the push of {progress.object_id}, gripper open"


def pushed(progress: Progress) -> bool:
    """The push recorded in `progress` ended (its retreat, or the way home, was started): the object stands at its
    end pose."""
    return any(phase in AFTER_PUSH for phase, _ in progress.moves)


def after_push(progress: Progress, made: PushPlan, q: np.ndarray, near: float
               ) -> list[tuple[str, Trajectory]] | None:
    """The rest of the push's plan from where the arm is, once its retreat was started (`progress`): the planned
    retreat or way home with the sample nearest q (largest joint difference; the later motion on a tie) if within
    `near`, from that sample, then the planned motions after it, each with its phase. None before the retreat, or
    off both."""
    if not pushed(progress):
        return None
    segs = [s for s in made.segments if PHASE[s.name] in AFTER_PUSH]
    best: tuple[float, int, int] | None = None
    for i, s in enumerate(segs):
        if not len(s.trajectory):
            continue
        d = np.max(np.abs(joint_error(s.trajectory.positions, q)), axis=1)
        k = int(np.argmin(d))
        if d[k] <= near and (best is None or d[k] <= best[0]):
            best = (float(d[k]), i, k)
    if best is None:
        return None
    first = segs[best[1]]
    return [(PHASE[first.name], first.trajectory.from_sample(best[2]))] + [(PHASE[s.name], s.trajectory)
                                                                           for s in segs[best[1] + 1:]]


def push_problems(shelf: Shelf, before: Mapping[str, Point], after: Mapping[str, SeenBottle], made: PushPlan,
                  tolerance: float, end_tolerance: float) -> list[str]:
    """What is wrong after the push `made` (empty: it did what it predicted): the pushed object (when `after` shows
    it) off the top shelf or farther than `end_tolerance` (m, on the board) from its predicted end pose (the centre
    of its footprint: a standing one's base, a lying one's middle); any other object in both scenes (`before`: base
    centres) moved more than `tolerance` (m, 3D)."""
    problems = []
    b = after.get(made.object_id)
    if b is not None:
        off = math.dist(b.footprint.centre, made.end[:2])
        if not on_top_shelf(shelf, b) or abs(b.z - made.end[2]) > tolerance:
            how = "lying" if made.kind in (SLIDE, ROLL) else "standing"
            problems.append(f"{made.object_id} is no longer {how} on the top shelf")
        elif off > end_tolerance:
            problems.append(f"{made.object_id} is {off * 1000:.0f} mm from its predicted end pose "
                            f"({made.end[0]:.3f}, {made.end[1]:.3f})")
    for i in sorted(set(before) & set(after) - {made.object_id}):
        q = after[i]
        d = math.dist(before[i], (q.x, q.y, q.z))
        if d > tolerance:
            problems.append(f"{i} moved {d * 1000:.0f} mm")
    return problems
