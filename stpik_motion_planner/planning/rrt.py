"""RRT-Connect with OMPL (paper Sect. 4.1, step 2): the end-effector path in Cartesian space, and for comparison
the same planner in joint space with the same collision checker.

Cartesian states are (x, y, z, yaw) of the tool of a horizontal side grasp (grasp.py); OMPL sees yaw scaled by
YAW_SCALE (m/rad) so that its Euclidean metric and motion-checking resolution are in metres. The validity check
is the rigid hand proxy (collision.HandProxy): no inverse kinematics inside the planner (IK goals make RRT-Connect
burn its budget: docs/install.md, "Platform notes"); the STPIK check (stpik.py) then decides whether the arm can
follow.

Budget: an attempt ends after `max_checks` validity checks (the work, the same on an idle or a loaded machine), so
a query's answer does not depend on the load. `deadline` (time.perf_counter()) is only a safety net: reached before
the checks are spent, `plan` raises SafetyNetTimeout, which is no answer (never "no path").

Randomness: every OMPL object that samples (RRT-Connect's state sampler, the nearest-neighbour structure's pivots,
the path simplifier) owns an `ompl::RNG` seeded, when it is built, from OMPL's process-wide seed sequence
(ompl/util/src/RandomNumbers.cpp). `RNG.setSeed` restarts that sequence even after sampling began (it logs "Random
number generation already started", then reseeds the sequence). Given `seed` (drawn from the question's generator,
PlannerParams.seed_per_query), `plan` restarts the sequence with it and then builds a fresh SimpleSetup and planner
under one process-wide lock: every RNG of that solve is then a function of the seed, so the path (simplification
included) is a function of the question only (docs/motion_planner.md, "Determinism"). Without `seed`: the sequence
seeded once per process (`seed_ompl`), paths depend on the queries run before.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Sequence

import numpy as np
import ompl.base as ob
import ompl.geometric as og
import ompl.util as ou
from numpy.typing import ArrayLike

from stpik_motion_planner.planning.budget import check_deadline

YAW_SCALE = 0.25  # metres of OMPL distance per radian of yaw
_seeded: list[int] = []
_SOLVING = threading.Lock()  # one OMPL solve at a time per process: no other thread draws from the seed sequence


def seed_ompl(seed: int) -> int:
    """Seed OMPL's process-wide RNG once (before any sampling). Returns the seed in effect."""
    if not _seeded:
        ou.setLogLevel(ou.LOG_ERROR)
        ou.RNG.setSeed(int(seed))
        _seeded.append(int(seed))
    return _seeded[0]


def _restart_seed_sequence(seed: int) -> None:
    """Restart OMPL's seed sequence at `seed` (>= 1): every RNG built afterwards draws its seed from it. The error
    OMPL logs for a reseed after sampling began is silenced: it warns about RNGs that already exist, and a seeded
    solve builds all of its own afterwards."""
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed))
    finally:
        ou.setLogLevel(level)


def _space(lo: Sequence[float] | np.ndarray, hi: Sequence[float] | np.ndarray) -> ob.RealVectorStateSpace:
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


def _solve(lo: np.ndarray, hi: np.ndarray, start: np.ndarray, goal: np.ndarray, valid: Callable[[np.ndarray], bool],
           max_checks: int, deadline: float, resolution: float, simplify_checks: int, planner_range: float,
           seed: int | None) -> list[np.ndarray] | None:
    """RRT-Connect in the box [lo, hi] until a path is found or `max_checks` validity checks are spent (then None);
    then OMPL's path simplification for `simplify_checks` more checks (0: none). With `seed` every RNG of the solve
    is seeded from it (module docstring)."""
    with _SOLVING:
        if seed is not None:
            _restart_seed_sequence(seed)
        return _solve_locked(_space(lo, hi), len(lo), start, goal, valid, max_checks, deadline, resolution,
                             simplify_checks, planner_range)


def _solve_locked(space: ob.RealVectorStateSpace, n: int, start: np.ndarray, goal: np.ndarray,
                  valid: Callable[[np.ndarray], bool], max_checks: int, deadline: float, resolution: float,
                  simplify_checks: int, planner_range: float) -> list[np.ndarray] | None:
    checks = [0]
    coords = range(n)

    def check(s: ob.State) -> bool:
        checks[0] += 1
        return valid(np.array([s[i] for i in coords]))

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

    def __init__(self, lo: ArrayLike, hi: ArrayLike, resolution: float, simplify_checks: int,
                 planner_range: float = 0.0) -> None:
        self.lo = np.array(lo, float)
        self.hi = np.array(hi, float)
        self.scale = np.array([1.0, 1.0, 1.0, YAW_SCALE])
        self.resolution = resolution
        self.simplify_checks = simplify_checks
        self.planner_range = planner_range
        self.checks = 0

    def contains(self, pose: ArrayLike) -> bool:
        """The pose is inside the planner's box (its position only, for 3 numbers)."""
        p = np.asarray(pose)
        n = len(p)
        return bool(np.all(p >= self.lo[:n] - 1e-9) and np.all(p <= self.hi[:n] + 1e-9))

    def plan(self, start: ArrayLike, goal: ArrayLike, valid: Callable[[np.ndarray], bool], max_checks: int,
             deadline: float, seed: int | None = None) -> list[np.ndarray] | None:
        """A path of poses from start to goal or None (budget spent); with `seed` a function of it (and the
        arguments) only, else of OMPL's process-wide RNG."""
        def check(s: np.ndarray) -> bool:
            self.checks += 1
            return valid(s / self.scale)

        path = _solve(self.lo * self.scale, self.hi * self.scale, np.asarray(start) * self.scale,
                      np.asarray(goal) * self.scale, check, max_checks, deadline, self.resolution,
                      self.simplify_checks, self.planner_range, seed)
        return None if path is None else [p / self.scale for p in path]


class JointRRT:
    """RRT-Connect in joint space (Q convention) between two configurations, for comparison in the benchmark."""

    def __init__(self, lo: ArrayLike, hi: ArrayLike, resolution: float, simplify_checks: int) -> None:
        self.lo, self.hi = np.array(lo, float), np.array(hi, float)
        self.resolution = resolution
        self.simplify_checks = simplify_checks
        self.checks = 0

    def plan(self, start: np.ndarray, goal: np.ndarray, valid: Callable[[np.ndarray], bool], max_checks: int,
             deadline: float, seed: int | None = None) -> list[np.ndarray] | None:
        """A path of configurations or None; with `seed` a function of it (and the arguments) only."""
        def check(q: np.ndarray) -> bool:
            self.checks += 1
            return valid(q)

        return _solve(self.lo, self.hi, start, goal, check, max_checks, deadline, self.resolution,
                      self.simplify_checks, 0.0, seed)
