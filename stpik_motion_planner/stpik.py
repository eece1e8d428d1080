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
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
import pinocchio as pin

from . import robot_description as rd
from .collision import PENETRATION, ArmGeometry, ObstacleSet
from .grasp import side_rotation
from .rrt import check_deadline


@dataclass
class StpikParams:
    dt: float = 0.04  # IK step (s); the output is resampled to 100 Hz
    ee_speed: float = 0.25  # m/s along the reference path
    approach_speed: float = 0.08  # m/s on the last straight approach to a grasp (no overshoot into the bottle)
    yaw_speed: float = 0.8  # rad/s
    k_pos: float = 8.0  # Eq. 9 gain K, position
    k_ori: float = 8.0  # orientation
    k_set: float = 8.0  # set-based tasks pushing back into their set
    k_posture: float = 0.3
    joint_margin: float = 0.05  # rad inside Table 6
    joint_buffer: float = 0.15  # rad: joint-limit tasks are candidates inside this band
    joint_act: float = 0.02  # rad: ... and enter when the next step would bring them this close to the limit
    self_clearance: float = 0.01  # m
    clearance: float = 0.015  # m, arm capsules to bottles and boards (the verified bound)
    buffer: float = 0.03  # m: distance tasks are candidates inside this band
    act: float = 0.004  # m: ... and enter when the next step would bring them this close to the bound
    violation_tol: float = 1e-3  # m or rad below a bound at an IK sample: reject
    track_tol: float = 0.03  # m along the path
    final_tol_pos: float = 0.004  # m at the end of the path
    final_tol_ori: float = 0.03  # rad
    settle_time: float = 1.0  # s allowed after the reference ends
    step_budget: float = 3.0  # IK steps allowed, in multiples of the reference's nominal steps (accepted: <= 1.22)
    damping: float = 0.05
    qdot_max: np.ndarray = field(default_factory=lambda: rd.QDOT_MAX.copy())

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "qdot_max":
                continue
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"motion planner parameter stpik.{f.name} must be a finite number >= 0, got {v!r}")
            setattr(self, f.name, float(v))
        try:
            q = np.array(self.qdot_max, dtype=float)
        except (TypeError, ValueError):
            q = np.zeros(0)
        if q.shape != (rd.N_JOINTS,) or not np.all(np.isfinite(q) & (q > 0)):
            raise ValueError(f"motion planner parameter stpik.qdot_max must be {rd.N_JOINTS} positive numbers "
                             f"(rad/s, Table 7), got {self.qdot_max!r}")
        self.qdot_max = q


@dataclass
class StpikResult:
    ok: bool
    reason: str
    q: np.ndarray  # (N+1) x 7 at times k * dt
    qdot: np.ndarray  # N x 7, constant over [k dt, (k+1) dt]
    dt: float
    min_clearance: float
    min_self_clearance: float
    steps: int


def hierarchy(levels, n: int, damping: float) -> np.ndarray:
    """Recursive null-space projection: qdot_k = qdot_{k-1} + (J_k N_{k-1})# (xdot_k - J_k qdot_{k-1}), with a
    damped pseudo-inverse near singularities. A level with jac None is the identity (a posture task, last)."""
    qdot = np.zeros(n)
    proj = np.eye(n)
    for jac, xd in levels:
        if jac is None:  # identity task (posture): its projection needs no decomposition
            return qdot + proj @ (xd - qdot)
        jt = jac @ proj
        u, s, vt = np.linalg.svd(jt, full_matrices=False)
        keep = s > 1e-6
        if not np.any(keep):
            continue
        u, s, vt = u[:, keep], s[keep], vt[keep]
        smin = s[-1]
        lam2 = damping ** 2 * (1.0 - (smin / damping) ** 2) if smin < damping else 0.0
        pinv = vt.T @ ((s / (s * s + lam2))[:, None] * u.T)
        qdot = qdot + pinv @ (xd - jac @ qdot)
        proj = proj - vt.T @ vt
    return qdot


class Stpik:
    """Tracks a Cartesian path [(x, y, z, yaw), ...] from a start configuration; see the module docstring."""

    def __init__(self, kin, arm: ArmGeometry, params: StpikParams) -> None:
        self.kin, self.arm, self.p = kin, arm, params
        self.lower = rd.Q_LOWER + params.joint_margin
        self.upper = rd.Q_UPPER - params.joint_margin
        self.eye = np.eye(rd.N_JOINTS)

    def _reference(self, path: list[np.ndarray], speed: float | None = None):
        """Piecewise-linear reference: cumulative times of the waypoints (at `speed`, default ee_speed)."""
        p = self.p
        speed = speed or p.ee_speed
        times = [0.0]
        for a, b in zip(path[:-1], path[1:]):
            dur = max(np.linalg.norm(b[:3] - a[:3]) / speed, abs(b[3] - a[3]) / p.yaw_speed, 1e-6)
            times.append(times[-1] + dur)
        return np.array(times)

    def track(self, q0, path: list[np.ndarray], obs: ObstacleSet, deadline: float,
              skip: dict[str, frozenset] | None = None, posture=None, speed: float | None = None,
              ramp: float = 0.0, accel: float = 0.0) -> StpikResult:
        """`ramp` > 0 (s): the reference accelerates from rest to its speed in `ramp` and decelerates to stop at
        every waypoint (trapezoidal in each segment) instead of starting at full speed and turning each corner at
        once. `accel` > 0 (rad/s^2): no joint velocity changes faster, also when a set-based task enters (a task
        entering changed the wrist's speed by 0.85 rad/s within one step: in the simulator the fingers then hit the
        bottle they held, 200-350 N, and it moved 18-25 mm in the hand for a few ms); the joint-limit tasks then
        enter early enough to stop within that acceleration. Both for a hand holding a bottle."""
        p = self.p
        kin, arm = self.kin, self.arm
        path = [np.asarray(w, float) for w in path]
        times = self._reference(path, speed)
        t_end = times[-1]
        posture = rd.Q_HOME if posture is None else np.asarray(posture, float)
        q = np.array(q0, float)
        qs, qdots = [q.copy()], []
        tau = 0.0  # reference time (slows down when joint velocities are scaled)
        settle = 0.0
        # each shape's clearance bound to obstacles: the planner's, or its own (a carried bottle's)
        bound = np.array([p.clearance if s.clearance is None else s.clearance for s in arm.specs])
        d_act = float(np.max(bound)) + p.buffer
        min_clear, min_self = math.inf, math.inf
        seg = 0
        rate = 0.0  # speed of the reference as a fraction of its nominal speed (ramp > 0)
        nominal = t_end + ramp * (len(path) - 1)  # a ramp adds about `ramp` s per segment
        max_steps = int(math.ceil((p.step_budget * nominal + p.settle_time) / p.dt))
        while True:
            check_deadline(deadline, "the STPIK check")
            if len(qdots) >= max_steps:
                return self._result(False, f"step budget spent ({max_steps} IK steps)", qs, qdots, min_clear,
                                    min_self)
            # reference pose and velocity at tau
            while seg < len(path) - 2 and tau >= times[seg + 1]:
                seg += 1
            a, b = path[seg], path[min(seg + 1, len(path) - 1)]
            t0, t1 = times[seg], times[min(seg + 1, len(path) - 1)]
            if tau >= t_end:
                ref, vel = path[-1], np.zeros(4)
            else:
                f = (tau - t0) / (t1 - t0)
                ref, vel = a + f * (b - a), (b - a) / (t1 - t0)
            if ramp > 0.0:
                rate = max(min(rate + p.dt / ramp, 1.0, math.sqrt(2.0 * max(t1 - tau, 0.0) / ramp)), p.dt / ramp)
                vel = vel * rate
            kin.update(q)
            arm.pose()
            rot, pos = kin.tool_pose()
            jt = kin.frame_jacobian(kin.tool_fid)
            e_p = ref[:3] - pos
            e_o = pin.log3(side_rotation(ref[3]) @ rot.T)
            ep_n, eo_n = float(np.linalg.norm(e_p)), float(np.linalg.norm(e_o))
            if tau >= t_end and ep_n < p.final_tol_pos and eo_n < p.final_tol_ori:
                return self._result(True, "reached", qs, qdots, min_clear, min_self)
            if ep_n > p.track_tol or eo_n > 10 * p.final_tol_ori + 0.2:
                return self._result(False, f"tracking failed (position error {ep_n:.3f} m)", qs, qdots,
                                    min_clear, min_self)
            if tau >= t_end:
                settle += p.dt
                if settle > p.settle_time:
                    return self._result(False, "did not converge at the goal", qs, qdots, min_clear, min_self)
            # set-based candidates: (group, sigma, jacobian row)
            cands = []
            for i in range(rd.N_JOINTS):
                lo, hi = q[i] - self.lower[i], self.upper[i] - q[i]
                if lo < p.joint_buffer:
                    cands.append((0, lo, self.eye[i], p.joint_act))
                if hi < p.joint_buffer:
                    cands.append((0, hi, -self.eye[i], p.joint_act))
            for i, j, d, pi, pj in arm.self_distances(p.self_clearance + p.buffer):
                min_self = min(min_self, d)
                n = pi - pj
                nn = np.linalg.norm(n)
                if nn < 1e-9:
                    return self._result(False, "self-collision", qs, qdots, min_clear, min_self)
                jac = (n / nn) @ (kin.point_jacobian(arm.fids[i], pi) - kin.point_jacobian(arm.fids[j], pj))
                cands.append((1, d - p.self_clearance, jac, p.act))
            for ci, o, d, pc, po in arm.obstacle_distances(obs, d_act, skip):
                if d == PENETRATION:
                    return self._result(False, f"{arm.specs[ci].name} collides with {o.name}", qs, qdots,
                                        -1.0, min_self)
                min_clear = min(min_clear, d)
                if d >= bound[ci] + p.buffer:
                    continue
                n = pc - po
                nn = np.linalg.norm(n)
                if nn < 1e-9:
                    return self._result(False, f"{arm.specs[ci].name} touches {o.name}", qs, qdots, 0.0, min_self)
                cands.append((2, d - bound[ci], (n / nn) @ kin.point_jacobian(arm.fids[ci], pc), p.act))
            for grp, sigma, _, _ in cands:
                if sigma < -p.violation_tol:
                    what = ("joint limit", "self-collision bound", "clearance bound")[grp]
                    return self._result(False, f"{what} violated ({sigma:.4f})", qs, qdots, min_clear, min_self)
            # Eq. 9 references of the equality tasks
            w_d = np.array([0.0, 0.0, vel[3]])
            eq_levels = [(jt[:3], vel[:3] + p.k_pos * e_p), (jt[3:], w_d + p.k_ori * e_o),
                         (None, p.k_posture * (posture - q))]
            active = [False] * len(cands)
            for _ in range(6):
                levels = []
                for grp in (0, 1, 2):
                    rows = [(c[2], p.k_set * max(0.0, c[3] - c[1])) for c, on in zip(cands, active)
                            if on and c[0] == grp]
                    if rows:
                        levels.append((np.array([r[0] for r in rows]), np.array([r[1] for r in rows])))
                qdot = hierarchy(levels + eq_levels, rd.N_JOINTS, p.damping)
                changed = False
                for k, (grp, sigma, jac, buf) in enumerate(cands):
                    v = float(jac @ qdot)
                    brake = 0.0
                    if accel > 0.0 and grp == 0 and qdots:  # the rate it can reach next step, and stop from
                        v = max(v, float(jac @ qdots[-1]) - accel * p.dt)
                        brake = v * v / (2.0 * accel)
                    if not active[k] and v < 0.0 and sigma + v * p.dt - brake < buf:
                        active[k] = changed = True
                if not changed:
                    break
            ratio = float(np.max(np.abs(qdot) / p.qdot_max))
            scale = 1.0 if ratio <= 1.0 else 1.0 / ratio
            qdot = qdot * scale
            if accel > 0.0 and qdots and tau < t_end:  # not while settling on the goal (slow by then)
                qdot = qdots[-1] + np.clip(qdot - qdots[-1], -accel * p.dt, accel * p.dt)
            q = q + qdot * p.dt
            qs.append(q.copy())
            qdots.append(qdot)
            if ramp > 0.0:  # each waypoint is reached, at the slowest rate, before the next segment starts
                tau = min(tau + p.dt * scale * rate, t1)
            else:
                tau = min(tau + p.dt * scale, t_end)

    def _result(self, ok, reason, qs, qdots, min_clear, min_self) -> StpikResult:
        return StpikResult(ok, reason, np.array(qs), np.array(qdots).reshape(-1, rd.N_JOINTS), self.p.dt,
                           min_clear, min_self, len(qdots))
