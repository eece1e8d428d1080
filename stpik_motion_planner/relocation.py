"""One relocation on a real or simulated arm (ROS-free): the sequence the RelocateObject action carries out.

home check -> plan_pick -> approach -> close the gripper -> plan_carry from the measured configuration -> carry ->
open -> retreat -> plan_home -> home. The destination is slot `len(removed)` of the bottom shelf (objects go
there in relocation order) and the objects already relocated stand in the earlier slots. The arm is anything
that implements `Arm`: the motion_planner node streams over ROS, the tests drive the MuJoCo core directly.
"""
from __future__ import annotations

from contextlib import nullcontext
from typing import Protocol

import numpy as np

from . import robot_description as rd
from .feasibility import MotionPlanner
from .trajectory import Trajectory

# progress (0..1) of the whole relocation at the start of each phase, in order
PHASES = {"plan_pick": 0.0, "approach": 0.05, "grasp": 0.35, "plan_carry": 0.4, "carry": 0.45, "release": 0.7,
          "retreat": 0.72, "plan_home": 0.8, "home": 0.82, "done": 1.0}


class Arm(Protocol):
    def measured(self) -> np.ndarray:
        """Current joint positions (Q convention, rad); raises if they cannot be had."""

    def follow(self, trajectory: Trajectory, phase: str) -> None:
        """Execute a planned motion until it settles; raises on failure."""

    def gripper(self, action: str, phase: str) -> None:
        """'close' (must grasp) or 'open'; returns once the fingers may be moved away; raises on failure."""

    def phase(self, phase: str) -> None:
        """A planning phase starts (progress reporting)."""


def relocate(planner: MotionPlanner, arm: Arm, object_id: str, removed: list[str], home_tol: float = 0.05,
             lock=None) -> None:
    """Relocate object_id to its slot; PlanningError (or the arm's error) names the failed stage. `lock` guards
    the planner (not thread-safe) while it plans, not while the arm moves."""
    lock = lock if lock is not None else nullcontext()
    removed = list(removed)
    slots = planner.scenario.slots
    placed = [(r, slots[k]) for k, r in enumerate(removed)]
    q = arm.measured()
    if float(np.max(np.abs(q - rd.Q_HOME))) > home_tol:
        arm.phase("plan_home")
        with lock:
            home = planner.plan_home(q, removed, placed)
        arm.follow(home, "home")
    arm.phase("plan_pick")
    with lock:
        (pick,) = planner.plan_pick(object_id, removed)
    arm.follow(pick.trajectory, "approach")
    arm.gripper("close", "grasp")
    arm.phase("plan_carry")
    q = arm.measured()
    with lock:
        carry, retreat = planner.plan_carry(object_id, removed, len(removed), q_start=q, placed=placed)
    arm.follow(carry.trajectory, "carry")
    arm.gripper("open", "release")
    arm.follow(retreat.trajectory, "retreat")
    arm.phase("plan_home")
    q = arm.measured()
    with lock:
        home = planner.plan_home(q, removed + [object_id], placed + [(object_id, slots[len(removed)])])
    arm.follow(home, "home")
    arm.phase("done")
