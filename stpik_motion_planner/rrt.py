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
another seed are ignored, and its Python bindings (ompl 2.0, nanobind) neither seed a planner's sampler nor let
Python replace it. So with OMPL a query's path is a function of the seed AND of the queries run before it in the
same process. Given `rng` (a numpy Generator seeded from the question, PlannerParams.seed_per_query), `plan` runs
`rrt_connect` instead: the same algorithm (Kuffner and LaValle 2000: two trees, extend then connect, OMPL's
default range of 0.2 x the space's extent) and budget, every sample drawn from `rng`, then a greedy shortcut of the
path; its path is a function of the question only. See docs/motion_planner.md, "Determinism".
"""
from __future__ import annotations

import math
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


def rrt_connect(start, goal, valid: Callable[[np.ndarray], bool], lo, hi, resolution: float, max_checks: int,
                deadline: float, rng: np.random.Generator, simplify_checks: int = 250,
                planner_range: float = 0.0) -> list[np.ndarray] | None:
    """RRT-Connect (two trees grown towards uniform samples of `rng` in [lo, hi], each new state connected greedily
    from the other tree) until a path or `max_checks` validity checks (then None); motions checked every
    `resolution`. Then `shortcut` with `simplify_checks` more checks. Deterministic given `rng`'s state."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    step = planner_range if planner_range > 0 else 0.2 * float(np.linalg.norm(hi - lo))
    checks = [0]

    def state_ok(s) -> bool:
        checks[0] += 1
        return bool(valid(s))

    def motion_ok(a, b) -> bool:  # the states after a, every `resolution`, b included
        n = max(1, int(math.ceil(float(np.linalg.norm(b - a)) / resolution)))
        return all(state_ok(a + (b - a) * (k / n)) for k in range(1, n + 1))

    start, goal = np.asarray(start, float), np.asarray(goal, float)
    if not (state_ok(start) and state_ok(goal)):
        return None
    trees = [([start], [-1]), ([goal], [-1])]

    def extend(tree, q) -> tuple[int, bool]:
        """(index of the new state or -1 if trapped, reached q)."""
        nodes, parents = tree
        i = int(np.argmin(np.sum((np.asarray(nodes) - q) ** 2, axis=1)))
        d = q - nodes[i]
        dist = float(np.linalg.norm(d))
        reached = dist <= step
        new = q if reached else nodes[i] + d * (step / dist)
        if dist == 0.0 or not motion_ok(nodes[i], new):
            return -1, False
        nodes.append(new)
        parents.append(i)
        return len(nodes) - 1, reached

    a = 0
    while checks[0] < max_checks:
        check_deadline(deadline, f"RRT-Connect ({checks[0]} of {max_checks} checks)")
        k, _ = extend(trees[a], rng.uniform(lo, hi))
        if k >= 0:
            q = trees[a][0][k]
            while checks[0] < max_checks:
                j, reached = extend(trees[1 - a], q)
                if j < 0:
                    break
                if reached:
                    ends = (k, j) if a == 0 else (j, k)
                    path = _branch(trees[0], ends[0])[::-1] + _branch(trees[1], ends[1])[1:]
                    return shortcut(path, motion_ok, checks, simplify_checks, deadline)
        a = 1 - a
    return None


def _branch(tree, k: int) -> list[np.ndarray]:
    """The states from node k up to the tree's root."""
    nodes, parents = tree
    out = []
    while k >= 0:
        out.append(nodes[k])
        k = parents[k]
    return out


def shortcut(path: list[np.ndarray], motion_ok, checks: list[int], budget: int, deadline: float) -> list[np.ndarray]:
    """Greedy vertex reduction: from each kept state, the farthest later state reachable by a valid straight
    motion, while `budget` validity checks last (then the rest of the path is kept as it is)."""
    limit = checks[0] + budget
    out, i = [path[0]], 0
    while i < len(path) - 1:
        check_deadline(deadline, "path shortcut")
        nxt = i + 1
        for j in range(len(path) - 1, i + 1, -1):
            if checks[0] >= limit:
                break
            if motion_ok(path[i], path[j]):
                nxt = j
                break
        out.append(path[nxt])
        i = nxt
    return out


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
        """The pose is inside the planner's box."""
        return bool(np.all(np.asarray(pose) >= self.lo - 1e-9) and np.all(np.asarray(pose) <= self.hi + 1e-9))

    def plan(self, start, goal, valid: Callable[[np.ndarray], bool], max_checks: int,
             deadline: float, rng: np.random.Generator | None = None) -> list[np.ndarray] | None:
        """A path of poses from start to goal or None (budget spent); OMPL's RRT-Connect, or `rrt_connect` drawing
        from `rng` when given (a path that depends on the question only)."""
        def check(s: np.ndarray) -> bool:
            self.checks += 1
            return valid(s / self.scale)

        if rng is not None:
            path = rrt_connect(np.asarray(start) * self.scale, np.asarray(goal) * self.scale, check,
                               self.lo * self.scale, self.hi * self.scale, self.resolution, max_checks, deadline,
                               rng, self.simplify_checks, self.planner_range)
            return None if path is None else [p / self.scale for p in path]
        space = _space(self.lo * self.scale, self.hi * self.scale)
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
             deadline: float, rng: np.random.Generator | None = None) -> list[np.ndarray] | None:
        """A path of configurations or None; OMPL's RRT-Connect, or `rrt_connect` drawing from `rng` when given."""
        def check(q: np.ndarray) -> bool:
            self.checks += 1
            return valid(q)

        if rng is not None:
            return rrt_connect(start, goal, check, self.lo, self.hi, self.resolution, max_checks, deadline, rng,
                               self.simplify_checks)
        space = _space(self.lo, self.hi)
        return _solve(space, len(self.lo), start, goal, check, max_checks, deadline, self.resolution,
                      self.simplify_checks, 0.0)
