"""Set-based Task-Priority Inverse Kinematics (paper Sect. 4.1, step 3; Eq. 9 and 10).

Closed-loop IK (Eq. 9): qdot = J# (xdot_d + K e), with the task hierarchy of Eq. 10 solved by recursive null-space
projection, highest priority first:
  1. joint limits (set-based: q_i in [Q_LOWER + margin, Q_UPPER - margin], Table 6, Q convention),
  2. self-collision avoidance (set-based: distance of non-adjacent capsules >= self_clearance),
  3. obstacle clearance (set-based: distance of arm capsules to bottles and boards >= clearance; a shape with its
     own bound, the carried bottle, >= that bound),
  4. end-effector position, 5. end-effector orientation, then a posture task towards Q_HOME (lowest).
A set-based task sigma >= 0 enters the hierarchy only when its bound is active (Moe et al. 2016, Di Lillo et al.):
it is a candidate while sigma is inside a buffer, and it is activated (as an equality task that freezes sigma,
or pushes it back up to the activation threshold `act`) when the solution without it would bring sigma below
`act`. Activation is iterated until no further task needs to enter.
The path is rejected if any bound is violated (sigma < -tol), if tracking error exceeds its tolerance, or when the
step budget is spent (step_budget times the reference's nominal steps, plus settle_time): IK steps, not seconds,
so the answer is the same on a loaded machine. The wall-clock deadline is only a safety net (SafetyNetTimeout: no
answer). Joint velocities are scaled to Table 7; the reference slows down by the same factor.

TrackMemo: checks reused across questions (the planner's own arm: the picks' paths). A check (Eq. 9-10 along a path)
is a function of its start, its path, its settings and of the obstacles its broad phase lets through
(ArmGeometry.near_pairs: an obstacle enters a step only when the axis-aligned box of some moving capsule comes
within the step's broad-phase distance d_act of its box). A check records, at every step it evaluated, the boxes of
the moving capsules; asked again with the same start, path and settings but another obstacle set, its result is
reused when every obstacle in one set and not in the other stays beyond d_act of the boxes of every evaluated step
(the same test as near_pairs), and the obstacles the two sets share come in the same order. Then every step sees the
same (capsule, obstacle) pairs in the same order, so it computes the same numbers: the reused result is the one the
check would give, bit for bit (by induction over the steps: the same configuration, the same pairs, the same step).
A change of the planner's parameters changes the key.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from collections import OrderedDict
from dataclasses import dataclass, field, fields
from typing import Any, Iterable, Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from relocation_common import robot_description as rd
from stpik_motion_planner.model.collision import PENETRATION, ArmGeometry, Obstacle, ObstacleSet, Skip
from stpik_motion_planner.model.grasp import pose_pitch, pose_roll, tool_rotation
from stpik_motion_planner.model.kinematics import Kinematics
from stpik_motion_planner.planning.budget import check_deadline

Level = tuple[np.ndarray | None, np.ndarray]  # one task of Eq. 10: (Jacobian, None for the identity; reference)
Candidates = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # set-based tasks: group, sigma, rows, threshold


@dataclass
class StpikParams:
    """STPIK's gains, bounds and tolerances (Eq. 9, 10): the stpik.* keys of config/motion_planner.yaml, their one
    place (planning.params.PlannerParams.load)."""

    dt: float  # IK step (s); the output is resampled to 100 Hz
    ee_speed: float  # m/s along the reference path
    approach_speed: float  # m/s on the last straight approach to a grasp (no overshoot into the bottle)
    yaw_speed: float  # rad/s
    k_pos: float  # Eq. 9 gain K, position
    k_ori: float  # orientation
    k_set: float  # set-based tasks pushing back into their set
    k_posture: float
    joint_margin: float  # rad inside Table 6
    joint_buffer: float  # rad: joint-limit tasks are candidates inside this band
    joint_act: float  # rad: ... and enter when the next step would bring them this close to the limit
    self_clearance: float  # m
    clearance: float  # m, arm capsules to bottles and boards (the verified bound)
    buffer: float  # m: distance tasks are candidates inside this band
    act: float  # m: ... and enter when the next step would bring them this close to the bound
    violation_tol: float  # m or rad below a bound at an IK sample: reject
    track_tol: float  # m along the path
    final_tol_pos: float  # m at the end of the path
    final_tol_ori: float  # rad
    grasp_yaw_tol: float  # rad about the vertical, at a grasp that did not converge within final_tol_ori
    settle_time: float  # s allowed after the reference ends
    step_budget: float  # IK steps allowed, in multiples of the reference's nominal steps
    damping: float  # of the pseudo-inverse near singularities

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"motion planner parameter stpik.{f.name} must be a finite number >= 0, got {v!r}")
            setattr(self, f.name, float(v))


@dataclass
class StpikResult:
    """One STPIK check: accepted or not (reason), the IK steps' configurations and rates."""

    ok: bool
    reason: str
    q: np.ndarray  # (N+1) x 7 at times k * dt
    qdot: np.ndarray  # N x 7, constant over [k dt, (k+1) dt]
    dt: float
    min_clearance: float
    min_self_clearance: float
    steps: int


try:  # the gufunc behind np.linalg.svd(a, full_matrices=False): the same LAPACK call without its Python wrapper
    from numpy.linalg import _umath_linalg as _ul

    _SVD_S: Any = _ul.svd_s
except (ImportError, AttributeError):  # pragma: no cover - another numpy layout
    _SVD_S = None


def _svd(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD of a small matrix (bit-identical to np.linalg.svd(a, full_matrices=False), less overhead)."""
    with np.errstate(invalid="ignore"):
        return _svd_quiet(a)


def _svd_quiet(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """_svd inside np.errstate(invalid="ignore") (the gufunc flags a failed decomposition so)."""
    if _SVD_S is not None:
        u, s, vt = _SVD_S(a, signature="d->ddd")
        if math.isfinite(s.dot(s)):  # no NaN (LAPACK did not converge) nor inf; an overflow only costs the call below
            return u, s, vt
    return np.linalg.svd(a, full_matrices=False)  # raises LinAlgError where it did not converge


@functools.lru_cache(maxsize=None)
def _eye(n: int) -> np.ndarray:
    """The n x n identity, made once (read only)."""
    eye = np.eye(n)
    eye.flags.writeable = False
    return eye


def hierarchy(levels: Iterable[Level], n: int, damping: float) -> np.ndarray:
    """Recursive null-space projection (Eq. 10): qdot_k = qdot_{k-1} + (J_k N_{k-1})# (xdot_k - J_k qdot_{k-1}), with a
    damped pseudo-inverse near singularities. A level with jac None is the identity (a posture task, last).
    The first level skips its products with N_0 = I and qdot_0 = 0 (exact in floating point)."""
    with np.errstate(invalid="ignore"):  # once for every level's SVD (_svd)
        return _hierarchy(levels, n, damping)


def _hierarchy(levels: Iterable[Level], n: int, damping: float) -> np.ndarray:
    """hierarchy's recursion."""
    qdot: np.ndarray | None = None
    proj: np.ndarray | None = None
    for jac, xd in levels:
        if jac is None:  # identity task (posture): its projection needs no decomposition
            return np.array(xd, float) if qdot is None else qdot + proj @ (xd - qdot)
        u, s, vt = _svd_quiet(jac if proj is None else jac @ proj)
        if not s[-1] > 1e-6:  # the singular values come in descending order: the last is the smallest
            keep = s > 1e-6
            if not keep.any():
                continue
            u, s, vt = u[:, keep], s[keep], vt[keep]
        smin = s[-1]
        lam2 = damping ** 2 * (1.0 - (smin / damping) ** 2) if smin < damping else 0.0
        pinv = vt.T @ ((s / (s * s + lam2))[:, None] * u.T)
        qdot = pinv @ xd if qdot is None else qdot + pinv @ (xd - jac @ qdot)
        vv = vt.T @ vt
        proj = _eye(n) - vv if proj is None else proj - vv
    return np.zeros(n) if qdot is None else qdot


@dataclass
class _Run:
    """The state of one STPIK check (Stpik.track)."""

    q: np.ndarray
    bound: np.ndarray  # each shape's clearance bound to obstacles
    d_act: float  # broad-phase distance: the largest bound + buffer
    qs: list[np.ndarray] = field(default_factory=list)
    qdots: list[np.ndarray] = field(default_factory=list)
    tau: float = 0.0  # reference time (slows down when joint velocities are scaled)
    settle: float = 0.0
    seg: int = 0
    rate: float = 0.0  # speed of the reference as a fraction of its nominal speed (ramp > 0)
    min_clear: float = math.inf
    min_self: float = math.inf
    yaw_tol: float = 0.0  # > 0: the goal's yaw tolerance once the settle time is spent (Stpik.track)
    from_rest: bool = False  # the accel limit holds from the first step (Stpik.track)
    boxes: list[tuple[np.ndarray, np.ndarray]] | None = None  # the moving capsules' boxes at each step (TrackMemo)
    q_eval: np.ndarray | None = None  # the configuration the last step evaluated

    @staticmethod
    def start(stpik: Stpik, q0: np.ndarray, yaw_tol: float, from_rest: bool,
              boxes: list[tuple[np.ndarray, np.ndarray]] | None) -> _Run:
        """A check's state at q0: each shape's clearance bound to obstacles (the planner's, or its own: a carried
        bottle's) and the broad-phase distance (the largest bound + buffer)."""
        p = stpik.p
        bound = np.array([p.clearance if s.clearance is None else s.clearance for s in stpik.arm.specs])
        return _Run(q0, bound, float(np.max(bound)) + p.buffer, yaw_tol=yaw_tol, from_rest=from_rest, boxes=boxes)


class _Reject(Exception):
    """A rejected path inside a step: the reason, and the minimum clearance to report if it overrides."""

    def __init__(self, reason: str, min_clear: float | None = None) -> None:
        super().__init__(reason)
        self.reason, self.min_clear = reason, min_clear


class Stpik:
    """Tracks a Cartesian path [(x, y, z, yaw), ...] (or [(x, y, z, yaw, pitch), ...]: grasp.tool_rotation) from a
    start configuration; see the module docstring."""

    def __init__(self, kin: Kinematics, arm: ArmGeometry, params: StpikParams) -> None:
        self.kin, self.arm, self.p = kin, arm, params
        self.lower = rd.Q_LOWER + params.joint_margin
        self.upper = rd.Q_UPPER - params.joint_margin
        self.eye = np.eye(rd.N_JOINTS)
        self.memo: TrackMemo | None = None  # checks reused across questions (TrackMemo), when given one

    def _reference(self, path: list[np.ndarray], speed: float | None = None) -> np.ndarray:
        """Piecewise-linear reference: cumulative times of the waypoints (at `speed`, default ee_speed)."""
        p = self.p
        speed = speed or p.ee_speed
        times = [0.0]
        for a, b in zip(path[:-1], path[1:]):
            dur = max(np.linalg.norm(b[:3] - a[:3]) / speed, abs(b[3] - a[3]) / p.yaw_speed, 1e-6)
            if len(a) > 4:  # the pitch of a grasp from above turns at the yaw's speed
                dur = max(dur, abs(b[4] - a[4]) / p.yaw_speed)
            times.append(times[-1] + dur)
        return np.array(times)

    def track(self, q0: ArrayLike, path: Sequence[ArrayLike], obs: ObstacleSet, deadline: float,
              skip: Skip | None = None, posture: ArrayLike | None = None, speed: float | None = None,
              ramp: float = 0.0, accel: float = 0.0, yaw_tol: float = 0.0, from_rest: bool = False) -> StpikResult:
        """Closed-loop IK (Eq. 9) with the hierarchy of Eq. 10 along `path`, from q0.
        `yaw_tol` > 0 (rad): a goal not reached within final_tol_ori when the settle time is spent is still
        reached if the tool is within final_tol_pos, its tilt within final_tol_ori and its rotation about the
        vertical within yaw_tol (a side grasp of a cylinder: `grasp_yaw_tol`). Every path that converged before
        converges as before, on the same steps.
        `ramp` > 0 (s): the reference accelerates from rest to its speed in `ramp` and decelerates to stop at
        every waypoint (trapezoidal in each segment) instead of starting at full speed and turning each corner at
        once. `accel` > 0 (rad/s^2): no joint velocity changes faster, also when a set-based task enters (a task
        entering changed the wrist's speed by 0.85 rad/s within one step: in the simulator the fingers then hit the
        bottle they held, 200-350 N, and it moved 18-25 mm in the hand for a few ms); the joint-limit tasks then
        enter early enough to stop within that acceleration. Both for a hand holding a bottle. `from_rest`: the arm
        is at rest at q0, so `accel` holds from the first step too (without it the first step is free).
        With a `memo` (TrackMemo), a check already run with the same start, path and settings is reused
        where the obstacles that differ stayed beyond its broad phase at every step: the same result, bit for bit."""
        waypoints = [np.asarray(w, float) for w in path]
        q0 = np.array(q0, float)
        posture = rd.Q_HOME if posture is None else np.asarray(posture, float)
        if self.memo is None:
            return self._track(_Run.start(self, q0, yaw_tol, from_rest, None), waypoints, obs, deadline, skip,
                               posture, speed, ramp, accel)
        key = self.memo.key(self.p, q0, waypoints, skip or {}, posture, speed, ramp, accel, yaw_tol, from_rest)
        check_deadline(deadline, "the STPIK check")
        got = self.memo.get(key, obs)
        if got is not None:  # the Kinematics and capsules left as the check left them
            self.kin.update(got.q_last)
            self.arm.pose()
            return _copy(got.result)
        run = _Run.start(self, q0, yaw_tol, from_rest, [])
        r = self._track(run, waypoints, obs, deadline, skip, posture, speed, ramp, accel)
        boxes = run.boxes or [(np.empty((0, 3)), np.empty((0, 3)))]
        self.memo.put(key, Checked(obs.items, np.vstack([b[0] for b in boxes]), np.vstack([b[1] for b in boxes]),
                                   run.d_act, _copy(r), run.q if run.q_eval is None else run.q_eval))
        return r

    def _track(self, run: _Run, waypoints: list[np.ndarray], obs: ObstacleSet, deadline: float, skip: Skip | None,
               posture: np.ndarray, speed: float | None, ramp: float, accel: float) -> StpikResult:
        """Stpik.track's loop from `run`'s start."""
        p = self.p
        times = self._reference(waypoints, speed)
        run.qs.append(run.q.copy())
        nominal = times[-1] + ramp * (len(waypoints) - 1)  # a ramp adds about `ramp` s per segment
        max_steps = int(math.ceil((p.step_budget * nominal + p.settle_time) / p.dt))
        while True:
            check_deadline(deadline, "the STPIK check")
            if len(run.qdots) >= max_steps:
                return self._result(False, f"step budget spent ({max_steps} IK steps)", run)
            ref, vel, t1 = self._reference_at(waypoints, times, run, ramp)
            try:
                scale = self._step(run, ref, vel, times[-1], obs, skip, posture, accel)
            except _Reject as e:
                if e.min_clear is not None:
                    run.min_clear = e.min_clear
                return self._result(e.reason == "reached", e.reason, run)
            if ramp > 0.0:  # each waypoint is reached, at the slowest rate, before the next segment starts
                run.tau = min(run.tau + p.dt * scale * run.rate, t1)
            else:
                run.tau = min(run.tau + p.dt * scale, times[-1])

    def _reference_at(self, path: list[np.ndarray], times: np.ndarray, run: _Run, ramp: float
                      ) -> tuple[np.ndarray, np.ndarray, float]:
        """Reference pose and velocity at run.tau (piecewise linear; trapezoidal speed with a ramp), segment end."""
        p = self.p
        while run.seg < len(path) - 2 and run.tau >= times[run.seg + 1]:
            run.seg += 1
        last = len(path) - 1
        a, b = path[run.seg], path[min(run.seg + 1, last)]
        t0, t1 = times[run.seg], times[min(run.seg + 1, last)]
        if run.tau >= times[-1]:
            ref, vel = path[-1], np.zeros(len(path[-1]))
        else:
            f = (run.tau - t0) / (t1 - t0)
            ref, vel = a + f * (b - a), (b - a) / (t1 - t0)
        if ramp > 0.0:
            run.rate = max(min(run.rate + p.dt / ramp, 1.0, math.sqrt(2.0 * max(t1 - run.tau, 0.0) / ramp)),
                           p.dt / ramp)
            vel = vel * run.rate
        return ref, vel, t1

    def _step(self, run: _Run, ref: np.ndarray, vel: np.ndarray, t_end: float, obs: ObstacleSet, skip: Skip | None,
              posture: np.ndarray, accel: float) -> float:
        """One IK step (Eq. 9-10) from run.q; returns the velocity scale of Table 7; raises _Reject to stop
        (reason "reached" when the goal is reached)."""
        p, kin = self.p, self.kin
        q = run.q
        kin.update(q)
        self.arm.pose()
        run.q_eval = q
        if run.boxes is not None:
            run.boxes.append(self.arm.moving_boxes())
        rot, pos = kin.tool_pose()
        jt = kin.frame_jacobian(kin.tool_fid)
        e_p = ref[:3] - pos
        e_o = pin.log3(tool_rotation(ref[3], pose_pitch(ref), pose_roll(ref)) @ rot.T)
        ep_n, eo_n = math.sqrt(e_p.dot(e_p)), math.sqrt(e_o.dot(e_o))  # np.linalg.norm's own formula
        if run.tau >= t_end and ep_n < p.final_tol_pos and eo_n < p.final_tol_ori:
            raise _Reject("reached")
        if ep_n > p.track_tol or eo_n > 10 * p.final_tol_ori + 0.2:
            raise _Reject(f"tracking failed (position error {ep_n:.3f} m)")
        if run.tau >= t_end:
            run.settle += p.dt
            if run.settle > p.settle_time:
                if run.yaw_tol > 0.0 and ep_n < p.final_tol_pos and math.hypot(e_o[0], e_o[1]) < p.final_tol_ori \
                        and abs(e_o[2]) < run.yaw_tol:
                    raise _Reject("reached")  # e_o is in the world frame: e_o[2] is the error about the vertical
                raise _Reject("did not converge at the goal")
        cands = self._set_tasks(run, obs, skip)
        # Eq. 9 references of the equality tasks
        w_d = np.array([0.0, 0.0, vel[3]])
        if len(vel) > 4:  # the pitch turns about tool x, horizontal: (-sin yaw, cos yaw, 0)
            w_d += vel[4] * np.array([-math.sin(ref[3]), math.cos(ref[3]), 0.0])
        if len(vel) > 5 and vel[5]:  # the roll turns about tool z (a push's hand keeps its roll: vel[5] 0)
            w_d += vel[5] * tool_rotation(ref[3], pose_pitch(ref), pose_roll(ref))[:, 2]
        eq_levels = [(jt[:3], vel[:3] + p.k_pos * e_p), (jt[3:], w_d + p.k_ori * e_o),
                     (None, p.k_posture * (posture - q))]
        prev = run.qdots[-1] if run.qdots else (np.zeros(rd.N_JOINTS) if run.from_rest else None)
        qdot = self._solve(cands, eq_levels, prev, accel)
        ratio = float((np.abs(qdot) / rd.QDOT_MAX).max())  # Table 7: the robot's
        scale = 1.0 if ratio <= 1.0 else 1.0 / ratio
        qdot = qdot * scale
        if accel > 0.0 and prev is not None and run.tau < t_end:  # not while settling on the goal (slow by then)
            qdot = prev + np.clip(qdot - prev, -accel * p.dt, accel * p.dt)
        run.q = q + qdot * p.dt
        run.qs.append(run.q.copy())
        run.qdots.append(qdot)
        return scale

    def _set_tasks(self, run: _Run, obs: ObstacleSet, skip: Skip | None) -> Candidates | None:
        """Set-based candidates of Eq. 10 at run.q as arrays (group, sigma, jacobian rows, activation threshold):
        joint limits (0), self-collision (1), obstacle clearance (2). Raises _Reject on a collision or a violated
        bound."""
        p, kin, arm = self.p, self.kin, self.arm
        q = run.q
        grp, sig, rows, buf = [], [], [], []
        lo, hi = q - self.lower, self.upper - q
        for k in np.nonzero((lo < p.joint_buffer) | (hi < p.joint_buffer))[0]:
            for s_, row in ((lo[k], self.eye[k]), (hi[k], -self.eye[k])):
                if s_ < p.joint_buffer:
                    grp.append(0)
                    sig.append(s_)
                    rows.append(row)
                    buf.append(p.joint_act)
        for i, j, d, pi, pj in arm.self_distances(p.self_clearance + p.buffer):
            run.min_self = min(run.min_self, d)
            n = pi - pj
            nn = math.sqrt(n.dot(n))
            if nn < 1e-9:
                raise _Reject("self-collision")
            jac = (n / nn) @ (kin.point_jacobian(arm.fids[i], pi) - kin.point_jacobian(arm.fids[j], pj))
            grp.append(1)
            sig.append(d - p.self_clearance)
            rows.append(jac)
            buf.append(p.act)
        bound = run.bound
        for ci, o, d, pc, po in arm.obstacle_distances(obs, run.d_act, skip):
            if d == PENETRATION:
                raise _Reject(f"{arm.specs[ci].name} collides with {o.name}", -1.0)
            run.min_clear = min(run.min_clear, d)
            if d >= bound[ci] + p.buffer:
                continue
            n = pc - po
            nn = math.sqrt(n.dot(n))
            if nn < 1e-9:
                raise _Reject(f"{arm.specs[ci].name} touches {o.name}", 0.0)
            grp.append(2)
            sig.append(d - bound[ci])
            buf.append(p.act)
            rows.append((n / nn) @ kin.point_jacobian(arm.fids[ci], pc))
        for g, s_ in zip(grp, sig):
            if s_ < -p.violation_tol:
                what = ("joint limit", "self-collision bound", "clearance bound")[g]
                raise _Reject(f"{what} violated ({s_:.4f})")
        if not grp:
            return None
        return np.array(grp), np.array(sig, float), np.array(rows), np.array(buf)

    def _solve(self, cands: Candidates | None, eq_levels: list[Level], prev: np.ndarray | None, accel: float
               ) -> np.ndarray:
        """Eq. 10 with the set-based tasks that must enter: a candidate is activated when the step without it would
        bring it within its threshold (with `accel`, joint limits early enough to stop); iterated."""
        p = self.p
        if cands is None:
            return hierarchy(eq_levels, rd.N_JOINTS, p.damping)
        grp, sig, jac, buf = cands
        active = np.zeros(len(grp), bool)
        qdot = np.zeros(rd.N_JOINTS)
        levels: list[Level] = []  # none active before the first pass
        for _ in range(6):
            qdot = hierarchy(levels + eq_levels, rd.N_JOINTS, p.damping)
            v = jac @ qdot
            brake: float | np.ndarray = 0.0
            if accel > 0.0 and prev is not None:  # the rate it can reach next step, and stop from
                lim = grp == 0
                v = np.where(lim, np.maximum(v, jac @ prev - accel * p.dt), v)
                brake = np.where(lim, v * v / (2.0 * accel), 0.0)
            new = ~active & (v < 0.0) & (sig + v * p.dt - brake < buf)
            if not new.any():
                break
            active |= new
            push = p.k_set * np.maximum(0.0, buf - sig)
            levels = [(jac[m], push[m]) for m in (active & (grp == g) for g in (0, 1, 2)) if m.any()]
        return qdot

    def _result(self, ok: bool, reason: str, run: _Run) -> StpikResult:
        return StpikResult(ok, reason, np.array(run.qs), np.array(run.qdots).reshape(-1, rd.N_JOINTS), self.p.dt,
                           run.min_clear, run.min_self, len(run.qdots))


def _copy(r: StpikResult) -> StpikResult:
    """A result with its own arrays (one kept by TrackMemo is never handed out)."""
    return dataclasses.replace(r, q=r.q.copy(), qdot=r.qdot.copy())


# ---------------------------------------------------------------- checks reused across questions (module docstring)
MAX_KEYS = 256  # (start, path, settings) kept, least recently used first out: a bound on memory, not on answers
MAX_PER_KEY = 4  # checks kept per key (obstacle sets that differ near the path)


@dataclasses.dataclass
class Checked:
    """One STPIK check as run: its obstacles, the moving capsules' boxes at each evaluated step, the broad-phase
    distance, the result, and the configuration the last step evaluated (the Kinematics state it left)."""

    items: list[Obstacle]
    lo: np.ndarray  # (evaluated steps x moving capsules) x 3
    hi: np.ndarray
    d_act: float
    result: StpikResult
    q_last: np.ndarray


class TrackMemo:
    """Checks by (start, path, settings), each reused for an obstacle set as the module docstring says."""

    def __init__(self) -> None:
        self.checks: OrderedDict[tuple, list[Checked]] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def clear(self) -> None:
        """Forget every check (a new scene)."""
        self.checks.clear()

    @staticmethod
    def key(params: object, q0: np.ndarray, path: Sequence[np.ndarray], *settings: object) -> tuple:
        """What a check is a function of besides its obstacles: the STPIK parameters, start, path and settings."""
        parts: list[Any] = [dataclasses.astuple(params), q0.tobytes()]  # type: ignore[call-overload]
        parts += [(len(w), w.tobytes()) for w in path]
        for s in settings:
            parts.append(s.tobytes() if isinstance(s, np.ndarray) else
                         tuple(sorted((k, tuple(sorted(v))) for k, v in s.items())) if isinstance(s, dict) else s)
        return tuple(parts)

    def get(self, key: tuple, obs: ObstacleSet) -> Checked | None:
        """A check of `key` valid for `obs` (the module docstring), or None."""
        for c in self.checks.get(key, ()):
            if c.items is obs.items or same_near(c, obs.items):
                self.checks.move_to_end(key)
                self.hits += 1
                return c
        self.misses += 1
        return None

    def put(self, key: tuple, check: Checked) -> None:
        """Keep `check` (the oldest keys and checks dropped beyond MAX_KEYS and MAX_PER_KEY)."""
        kept = self.checks.setdefault(key, [])
        kept.insert(0, check)
        del kept[MAX_PER_KEY:]
        self.checks.move_to_end(key)
        while len(self.checks) > MAX_KEYS:
            self.checks.popitem(last=False)


def same_near(c: Checked, items: list[Obstacle]) -> bool:
    """Whether a check run with c.items sees the same pairs at every step with `items`: the shared obstacles in the
    same order, and each obstacle of one set only beyond c.d_act of every evaluated step's capsule boxes."""
    old = {id(o) for o in c.items}
    new = {id(o) for o in items}
    if [id(o) for o in c.items if id(o) in new] != [id(o) for o in items if id(o) in old]:
        return False
    diff = [o for o in items if id(o) not in old] + [o for o in c.items if id(o) not in new]
    if not diff:
        return True
    lo = np.array([o.lo for o in diff])
    hi = np.array([o.hi for o in diff])
    gap = np.maximum(np.maximum(lo[None] - c.hi[:, None], c.lo[:, None] - hi[None]), 0.0)
    # near_pairs' test (gap^2 < d_act^2), with a margin for rounding: a pair it could let through is never missed
    return not bool((np.einsum("ijk,ijk->ij", gap, gap) < c.d_act * c.d_act * (1.0 + 1e-6) + 1e-12).any())
