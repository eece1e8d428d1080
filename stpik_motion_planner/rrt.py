"""RRT-Connect with OMPL (paper Sect. 4.1, step 2): the end-effector path in Cartesian space, and for comparison
the same planner in joint space with the same collision checker.

Cartesian states are (x, y, z, yaw) of the tool of a horizontal side grasp (grasp.py); OMPL sees yaw scaled by
YAW_SCALE (m/rad) so that its Euclidean metric and motion-checking resolution are in metres. The validity check
is the rigid hand proxy (collision.HandProxy): no inverse kinematics inside the planner (see STACK-NOTES: IK
goals make RRT-Connect burn its budget); the STPIK check (stpik.py) then decides whether the arm can follow.

Budget: an attempt ends after `max_checks` validity checks (the work, the same on an idle or a loaded machine), so
a query's answer does not depend on the load. `deadline` (time.perf_counter()) is only a safety net: reached before
the checks are spent, `plan` raises SafetyNetTimeout, which is no answer (never "no path").

Randomness: OMPL has one RNG per process, seeded once (`seed_ompl`) before any sampling; later calls with
another seed are ignored. So a query's path is a function of the seed AND of the queries run before it in the
same process. See docs/motion_planner.md.
"""
from __future__ import annotations

import time
from typing import Callable, Sequence

import numpy as np
import ompl.base as ob
import ompl.geometric as og
import ompl.util as ou

from .budget import check_deadline

YAW_SCALE = 0.25  # metres of OMPL distance per radian of yaw
_seeded: list[int] = []


def seed_ompl(seed: int) -> int:
    """Seed OMPL's process-wide RNG once (before any sampling). Returns the seed in effect."""
    if not _seeded:
        ou.setLogLevel(ou.LOG_ERROR)
        ou.RNG.setSeed(int(seed))
        _seeded.append(int(seed))
    return _seeded[0]


def _space(lo: Sequence[float], hi: Sequence[float]) -> ob.RealVectorStateSpace:
    n = len(lo)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i in range(n):
        bounds.setLow(i, float(lo[i]))
        bounds.setHigh(i, float(hi[i]))
    space.setBounds(bounds)
    return space


def _budget(checks: list[int], limit: int, deadline: float) -> ob.PlannerTerminationCondition:
    """Stop once checks[0] reaches `limit`, or at the wall-clock deadline (the caller tells which)."""
    spent = ob.PlannerTerminationCondition(lambda: checks[0] >= limit)
    return ob.plannerOrTerminationCondition(spent, ob.timedPlannerTerminationCondition(
        max(deadline - time.perf_counter(), 1e-3)))


def _solve(space, n: int, start, goal, valid: Callable[[np.ndarray], bool], max_checks: int, deadline: float,
           resolution: float, simplify_checks: int, planner_range: float) -> list[np.ndarray] | None:
    """RRT-Connect until a path is found or `max_checks` validity checks are spent (then None); then OMPL's
    path simplification for `simplify_checks` more checks (0: none)."""
    checks = [0]

    def check(s) -> bool:
        checks[0] += 1
        return valid(np.fromiter((s[i] for i in range(n)), float, n))

    ss = og.SimpleSetup(space)
    ss.setStateValidityChecker(check)
    si = ss.getSpaceInformation()
    si.setStateValidityCheckingResolution(resolution / space.getMaximumExtent())
    a, b = space.allocState(), space.allocState()
    for i in range(n):
        a[i], b[i] = float(start[i]), float(goal[i])
    ss.setStartAndGoalStates(a, b)
    planner = og.RRTConnect(si)
    if planner_range > 0:
        planner.setRange(planner_range)
    ss.setPlanner(planner)
    solved = ss.solve(_budget(checks, max_checks, deadline)) and ss.haveExactSolutionPath()
    if not solved:
        if checks[0] < max_checks:
            check_deadline(deadline, f"RRT-Connect ({checks[0]} of {max_checks} checks)")
        return None
    if simplify_checks > 0:
        ss.simplifySolution(_budget(checks, checks[0] + simplify_checks, deadline))
        check_deadline(deadline, "path simplification")
    path = ss.getSolutionPath()
    return [np.array([path.getState(k)[i] for i in range(n)]) for k in range(path.getStateCount())]


class CartesianRRT:
    """RRT-Connect over (x, y, z, yaw) within a box; `plan` returns a list of poses or None."""

    def __init__(self, lo: Sequence[float], hi: Sequence[float], resolution: float = 0.01,
                 simplify_checks: int = 250, planner_range: float = 0.0) -> None:
        self.lo = np.array(lo, float)
        self.hi = np.array(hi, float)
        self.scale = np.array([1.0, 1.0, 1.0, YAW_SCALE])
        self.resolution = resolution
        self.simplify_checks = simplify_checks
        self.planner_range = planner_range
        self.checks = 0

    def contains(self, pose) -> bool:
        return bool(np.all(np.asarray(pose) >= self.lo - 1e-9) and np.all(np.asarray(pose) <= self.hi + 1e-9))

    def plan(self, start, goal, valid: Callable[[np.ndarray], bool], max_checks: int,
             deadline: float) -> list[np.ndarray] | None:
        space = _space(self.lo * self.scale, self.hi * self.scale)

        def check(s: np.ndarray) -> bool:
            self.checks += 1
            return valid(s / self.scale)

        path = _solve(space, 4, np.asarray(start) * self.scale, np.asarray(goal) * self.scale, check, max_checks,
                      deadline, self.resolution, self.simplify_checks, self.planner_range)
        return None if path is None else [p / self.scale for p in path]


class JointRRT:
    """RRT-Connect in joint space (Q convention) between two configurations, for comparison in the benchmark."""

    def __init__(self, lo: Sequence[float], hi: Sequence[float], resolution: float = 0.02,
                 simplify_checks: int = 250) -> None:
        self.lo, self.hi = np.array(lo, float), np.array(hi, float)
        self.resolution = resolution
        self.simplify_checks = simplify_checks
        self.checks = 0

    def plan(self, start, goal, valid: Callable[[np.ndarray], bool], max_checks: int,
             deadline: float) -> list[np.ndarray] | None:
        space = _space(self.lo, self.hi)

        def check(q: np.ndarray) -> bool:
            self.checks += 1
            return valid(q)

        return _solve(space, len(self.lo), start, goal, check, max_checks, deadline, self.resolution,
                      self.simplify_checks, 0.0)
