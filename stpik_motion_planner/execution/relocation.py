"""One relocation on a real or simulated arm (ROS-free): the sequence the RelocateObject action carries out.

plan the whole relocation (pick, carry, retreat, home) -> [the way home first, if the arm is away from it] ->
approach -> close the gripper -> re-plan the carry from the measured configuration (the plan made before is kept if
that fails) -> carry -> open -> retreat -> re-plan home from the measured configuration (idem) -> home.
Nothing moves before the whole relocation is planned, so a carry that cannot be planned never leaves the arm
holding a bottle; and when a motion fails or the goal is cancelled, `recover` brings the arm back to a safe state
along the motions it made (the bottle set down where it was picked, the arm home; after the release, on along the
retreat first). The destination is the slot the caller chose (the motion_planner node: a free one of the scene,
goal_check.destination) with the bottles placed so far where they stand; by default slot `len(removed)`, the
objects already relocated in the earlier slots. The arm is anything that implements `Arm`: the motion_planner node
streams over ROS, the tests drive the MuJoCo core directly.
"""
from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Callable, ContextManager, Protocol

import numpy as np

from relocation_common import robot_description as rd
from stpik_motion_planner.execution.follower import joint_error
from stpik_motion_planner.model.grasp import WorkspaceError
from stpik_motion_planner.planning.budget import SafetyNetTimeout
from stpik_motion_planner.planning.context import Placed
from stpik_motion_planner.planning.params import node_parameters
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.results import PlanningError
from stpik_motion_planner.planning.trajectory import Trajectory

# progress (0..1) of the whole relocation at the start of each phase, in order
PHASES = {"plan_pick": 0.0, "approach": 0.05, "grasp": 0.35, "plan_carry": 0.4, "carry": 0.45, "release": 0.7,
          "retreat": 0.72, "plan_home": 0.8, "home": 0.82, "done": 1.0, "recover": 1.0}
# ... and of a push (execution/push.py): the gripper shut, the approach, the push, the retreat, the way home, opened
PUSH_PHASES = {"plan_push": 0.0, "shut": 0.05, "approach_push": 0.1, "push": 0.4, "retreat_push": 0.6,
               "home_push": 0.7, "open": 0.95, "pushed": 1.0, "recover_push": 1.0}


class Arm(Protocol):
    """The arm a relocation runs on: measured joints, motion, gripper and phase reports."""

    def measured(self) -> np.ndarray:
        """Current joint positions (Q convention, rad); raises if they cannot be had."""

    def follow(self, trajectory: Trajectory, phase: str) -> None:
        """Execute a planned motion until it settles; raises on failure."""

    def gripper(self, action: str, phase: str) -> None:
        """'close' (must grasp), 'shut' (closed on nothing: a push's hand) or 'open'; returns once the fingers may be
        moved away; raises on failure."""

    def phase(self, phase: str) -> None:
        """A planning phase starts (progress reporting)."""


@dataclass
class Progress:
    """What a relocation has done so far, for `recover`: the motions followed (the current one included)."""

    object_id: str = ""
    removed: list = field(default_factory=list)
    placed: list = field(default_factory=list)  # (bottle, slot xy) on the bottom shelf, this one once released
    moves: list = field(default_factory=list)  # (phase, Trajectory), oldest first; a recovery removes those undone
    released: bool = False
    carried: bool = False  # the carry was gone back along by a recovery (a retry says so)


@dataclass
class RelocationPlan:
    """Every motion of one relocation, planned from the home configuration before the arm moves."""

    object_id: str
    slot_index: int
    placed: list  # (id, slot xy) of the objects on the bottom shelf before this one
    pick: Trajectory  # home -> pre-grasp -> grasp, then close
    carry: Trajectory  # lift, out of the shelf, in to the slot, then open
    retreat: Trajectory  # back to the staging pose
    home: Trajectory  # staging pose -> home


def plan_relocation(planner: MotionPlanner, object_id: str, removed: list[str], slot: int | None = None,
                    placed: list | None = None) -> RelocationPlan:
    """The whole relocation of object_id to slot `slot` with the bottles `placed` ((id, (x, y))) on the bottom
    shelf; by default slot len(removed), the objects of `removed` (in relocation order) in the earlier slots.
    PlanningError names the stage that failed (an unreachable pose or slot included)."""
    removed = list(removed)
    slots = planner.scenario.slots
    k = len(removed) if slot is None else slot
    if k >= len(slots):
        raise PlanningError(f"no free slot for {object_id!r}: {k} objects relocated, the scenario has "
                            f"{len(slots)} slots")
    placed = [(r, slots[j]) for j, r in enumerate(removed)] if placed is None else list(placed)
    try:
        (pick,) = planner.plan_pick(object_id, removed)
    except WorkspaceError as e:
        raise PlanningError(f"pick of {object_id!r}: {e}") from None
    carry, retreat = planner.plan_carry(object_id, removed, k, q_start=pick.trajectory.positions[-1], placed=placed)
    home = planner.plan_home(retreat.trajectory.positions[-1], removed + [object_id],
                             placed + [(object_id, slots[k])])
    return RelocationPlan(object_id, k, placed, pick.trajectory, carry.trajectory, retreat.trajectory, home)


def relocate(planner: MotionPlanner, arm: Arm, object_id: str, removed: list[str], home_tol: float | None = None,
             lock: ContextManager[object] | None = None, progress: Progress | None = None, slot: int | None = None,
             placed: Placed | None = None, on_change: Callable[[], None] = lambda: None) -> RelocationPlan:
    """Relocate object_id to its slot (`slot` and `placed` as plan_relocation); PlanningError (or the arm's error)
    names the failed stage. `lock` guards the planner (not thread-safe) while it plans, not while the arm moves.
    `progress` records what was done (for `recover` after a failure); `on_change()` is called each time it changes
    (a motion about to start, the release: the node's journal). Farther than `home_tol` (rad; None:
    config/motion_planner.yaml's) from home, the arm goes home first. Returns the plan made before moving."""
    lock = lock if lock is not None else nullcontext()
    home_tol = float(node_parameters()["home_tol"]) if home_tol is None else home_tol
    removed = list(removed)
    arm.phase("plan_pick")
    with lock:
        plan = plan_relocation(planner, object_id, removed, slot, placed)
    slot_xy = planner.scenario.slots[plan.slot_index]
    progress = progress if progress is not None else Progress()
    progress.object_id, progress.removed, progress.placed = object_id, removed, list(plan.placed)
    arm = _Recorded(arm, progress, on_change)
    q = arm.measured()
    if float(np.max(np.abs(q - rd.Q_HOME))) > home_tol:
        arm.phase("plan_home")
        with lock:
            home = planner.plan_home(q, removed, plan.placed)
        arm.follow(home, "home")
    arm.follow(plan.pick, "approach")
    arm.gripper("close", "grasp")
    arm.phase("plan_carry")
    carry, retreat = plan.carry, plan.retreat
    q = arm.measured()
    with lock:
        try:  # from where the arm really is; the plan made before is within the follower's settling tolerance
            c, r = planner.plan_carry(object_id, removed, plan.slot_index, q_start=q, placed=plan.placed)
            carry, retreat = c.trajectory, r.trajectory
        except (PlanningError, SafetyNetTimeout):  # the safety net under load: the plan made before is as good
            pass
    arm.follow(carry, "carry")
    arm.gripper("open", "release")
    progress.released = True
    progress.placed.append((object_id, slot_xy))
    on_change()
    arm.follow(retreat, "retreat")
    arm.phase("plan_home")
    home = plan.home
    q = arm.measured()
    with lock:
        try:
            home = planner.plan_home(q, removed + [object_id], plan.placed + [(object_id, slot_xy)])
        except (PlanningError, SafetyNetTimeout):  # idem: a bottle released, the arm must still come home
            pass
    arm.follow(home, "home")
    arm.phase("done")
    return plan


class _Recorded:
    """An Arm that records each motion in a Progress (then calls on_change) before following it."""

    def __init__(self, arm: Arm, progress: Progress, on_change: Callable[[], None]) -> None:
        self.arm, self.progress, self.on_change = arm, progress, on_change
        self.measured, self.gripper, self.phase = arm.measured, arm.gripper, arm.phase

    def follow(self, trajectory: Trajectory, phase: str) -> None:
        self.progress.moves.append((phase, trajectory))
        self.on_change()
        self.arm.follow(trajectory, phase)


def recover(planner: MotionPlanner, arm: Arm, progress: Progress, lock: ContextManager[object] | None = None,
            on_change: Callable[[], None] = lambda: None, near: float | None = None) -> str:
    """A safe state after a failed or cancelled relocation (the next goal starts from home, nothing held).

    Before the release: back along the motions made, newest first (the same paths, as clear as on the way there);
    the way back along the carry ends at the grasp, where a held bottle is let go, standing where it was picked; then
    back along the approach to home. Each motion gone back along leaves `progress.moves` (then on_change(): the
    journal), so a recovery tried again goes on from where the arm is with the motions left: before, a retry after
    the last motion failed near home (did not settle under load) went back along the whole carry again, from its
    sample nearest home into the shelf. After the release: on along the motion made since that the arm is on
    (`after_release`: the retreat away from the bottle, or the way home), then a path home from where it ends; from
    the slot itself a fresh path home started in collision (the open fingers around the bottle just placed) and the
    arm stayed there. `near`: rad (None: config/motion_planner.yaml's recover_near). Returns what was done; raises
    (the arm's or PlanningError) if it could not."""
    lock = lock if lock is not None else nullcontext()
    if progress.released:
        near = float(node_parameters()["recover_near"]) if near is None else near
        on = after_release(progress, arm.measured(), near)
        if on is not None:
            arm.follow(on[1], "recover")
            if on[0] == "home":
                return f"{progress.object_id} was placed; arm on along its way home"
        with lock:
            home = planner.plan_home(arm.measured(), progress.removed + [progress.object_id], progress.placed)
        arm.follow(home, "recover")
        return f"{progress.object_id} was placed; arm " + (f"on along its {on[0]}, then " if on else "") + "back home"
    moves = [(phase, t) for phase, t in progress.moves if phase in ("approach", "carry")]
    carried = any(phase == "carry" for phase, _ in moves) or progress.carried
    if not moves and not progress.carried:
        return "arm stopped (it had not moved towards the bottle)"
    for phase, traj in reversed(moves):
        if phase == "approach":  # at the grasp: let go of the bottle (if held) where it was picked
            arm.gripper("open", "recover")
        arm.follow(traj.back_from(arm.measured()), "recover")
        progress.carried |= phase == "carry"
        progress.moves = [m for m in progress.moves if m[1] is not traj]  # gone back along: not again
        on_change()
    return (f"{progress.object_id} set down where it was picked; arm back home" if carried else
            "arm back home along its approach, gripper open")


def after_release(progress: Progress, q: np.ndarray, near: float) -> tuple[str, Trajectory] | None:
    """The rest of the motion made after the release that the arm is on: of the retreat and the way home recorded
    after the last carry (both planned with the bottle at its slot, each toward its clear end: the staging pose,
    home), the one with the sample nearest q (largest joint difference, follower.joint_error; the later one on a tie)
    if that is within `near`; (its phase, its samples from that one to its end). None when the arm is on neither."""
    carry = max((i for i, (phase, _) in enumerate(progress.moves) if phase == "carry"), default=-1)
    best: tuple[float, str, Trajectory, int] | None = None
    for phase, t in progress.moves[carry + 1:]:
        if phase not in ("retreat", "home") or not len(t):
            continue
        d = np.max(np.abs(joint_error(t.positions, q)), axis=1)
        k = int(np.argmin(d))
        if d[k] <= near and (best is None or d[k] <= best[0]):
            best = (float(d[k]), phase, t, k)
    return None if best is None else (best[1], best[2].from_sample(best[3]))
