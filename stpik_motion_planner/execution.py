"""Following a planned joint trajectory with joint-velocity commands (ROS-free; the motion_planner node streams it).

The command at time t is the planned velocity (feed-forward, Eq. 9's q̇ as the STPIK check produced it) plus a
proportional correction towards the planned position, clamped to Table 7:

    q̇_cmd(t) = q̇_ref(t) + k_track * (q_ref(t) - q_measured),   |q̇_cmd,i| <= q̇_max,i

After the reference ends the follower keeps correcting until every joint is within `settle_tol` of the last
position (it "settles"), or reports a failure after `settle_timeout`. A tracking error above `max_error` at any
time is a failure too (the arm is blocked, or it is not where the plan starts).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import robot_description as rd
from .trajectory import Trajectory


@dataclass(frozen=True)
class FollowerParams:
    k_track: float = 4.0  # 1/s, position correction gain
    settle_tol: float = 0.01  # rad, every joint at the end of the trajectory
    settle_timeout: float = 3.0  # s after the reference ends
    max_error: float = 0.2  # rad, largest tracking error before the motion is aborted

    def __post_init__(self) -> None:
        for k in ("k_track", "settle_tol", "settle_timeout", "max_error"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"follower parameter {k} must be a positive number, got {v!r}")


def joint_error(q_ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """q_ref - q, wrapped to (-pi, pi] on the continuous joints (1, 3, 5, 7)."""
    e = np.asarray(q_ref, float) - np.asarray(q, float)
    cont = np.array(rd.CONTINUOUS)
    e[cont] = (e[cont] + math.pi) % (2 * math.pi) - math.pi
    return e


class TrajectoryFollower:
    RUNNING, SETTLED, FAILED = "running", "settled", "failed"

    def __init__(self, trajectory: Trajectory, qdot_max=rd.QDOT_MAX, params: FollowerParams | None = None):
        if len(trajectory) == 0:
            raise ValueError("cannot follow an empty trajectory")
        self.traj = trajectory
        self.qdot_max = np.asarray(qdot_max, float)
        self.p = params or FollowerParams()
        self.reason = ""

    @property
    def duration(self) -> float:
        return self.traj.duration

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Planned position (interpolated) and velocity (held) at time t; after the end, the last point, 0."""
        tr = self.traj
        if t >= tr.duration:
            return tr.positions[-1], np.zeros(rd.N_JOINTS)
        k = int(np.clip(np.searchsorted(tr.times, t, side="right") - 1, 0, len(tr.times) - 1))
        return tr.positions[k] + tr.velocities[k] * (t - tr.times[k]), tr.velocities[k]

    def command(self, t: float, q: np.ndarray) -> np.ndarray:
        """Joint velocities (rad/s) to send at time t given the measured configuration q."""
        q = np.asarray(q, float)
        if q.shape != (rd.N_JOINTS,) or not np.all(np.isfinite(q)):
            raise ValueError(f"measured configuration must be 7 finite angles, got {q!r}")
        q_ref, v_ff = self.reference(t)
        v = v_ff + self.p.k_track * joint_error(q_ref, q)
        return np.clip(v, -self.qdot_max, self.qdot_max)

    def status(self, t: float, q: np.ndarray) -> str:
        q_ref, _ = self.reference(t)
        err = float(np.max(np.abs(joint_error(q_ref, q))))
        if err > self.p.max_error:
            self.reason = f"tracking error {err:.3f} rad > max_error {self.p.max_error} rad at t={t:.2f} s"
            return self.FAILED
        if t >= self.duration:
            if err <= self.p.settle_tol:
                return self.SETTLED
            if t > self.duration + self.p.settle_timeout:
                self.reason = (f"did not settle within {self.p.settle_timeout} s: error {err:.3f} rad "
                               f"> settle_tol {self.p.settle_tol} rad")
                return self.FAILED
        return self.RUNNING
