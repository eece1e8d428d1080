"""Following a planned joint trajectory with joint-velocity commands (ROS-free; the motion_planner node streams it).

The command is the planned velocity at the reference time tau (feed-forward: the q̇ of Eq. 9 that the STPIK check
produced), scaled by the time-scaling rate s, plus a proportional correction towards the planned position,
clamped to Table 7:

    q̇_cmd = s q̇_ref(tau) + k_track (q_ref(tau) - q_measured),   tau advances by s dt,   |q̇_cmd,i| <= q̇_max,i

s = 1 while the tracking error e (largest joint) is below `lag_tol` and falls linearly to 0 at 2 lag_tol: a late
command stream or a slow simulator makes the reference wait for the arm, which catches up on the planned path
instead of cutting corners (the STPIK check slows its reference the same way). One update advances tau by at most
`max_step`: when the stream itself stalls (a loaded machine: the update comes 0.3 s late), the driver has stopped
the arm after its watchdog, and a reference that jumped by the whole gap would be 0.3 rad ahead of it at once.
Without the scaling the feed-forward would hold the arm at e = q̇_ref / k_track off the path.
After the end the follower corrects until every joint has stayed within
`settle_tol` of the last point for `settle_dwell`: the joint states it closes the loop on can be a tenth of a
second old under load (the subscription's queue), and a follower that stopped at the first state within settle_tol
left the arm where the correction on those old states had carried it, past the point (0.044 rad off home after a
recovery; 0.040 rad in MuJoCo with states 0.1 s old: test_execution.py). Failures: an error above `max_error`, tau
stuck for `stall_timeout` (the arm is blocked), or no settling within `settle_timeout`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numpy.typing import ArrayLike

from relocation_common import robot_description as rd
from stpik_motion_planner.planning.params import node_parameters
from stpik_motion_planner.planning.trajectory import Trajectory

PREFIX = "follower."  # of the follower's keys among the motion_planner node's parameters

@dataclass(frozen=True)
class FollowerParams:
    """Gains and tolerances of the trajectory follower (see the module docstring): the follower.* keys of
    config/motion_planner.yaml, their one place (`load`)."""

    k_track: float  # 1/s, position correction gain
    lag_tol: float  # rad: above this tracking error the reference slows down (stops at twice it)
    settle_tol: float  # rad, every joint at the end of the trajectory
    settle_timeout: float  # s after the reference ends
    settle_dwell: float  # s every joint stays within settle_tol before the motion counts as settled
    stall_timeout: float  # s with the reference waiting before the motion is aborted
    max_error: float  # rad, largest tracking error before the motion is aborted
    max_step: float  # s: the most the reference advances in one update (a gap in the stream: the arm stood still)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"follower parameter {f.name} must be a positive number, got {v!r}")

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The node's parameter names: follower.<field>."""
        return tuple(f"{PREFIX}{f.name}" for f in fields(cls))

    @classmethod
    def from_mapping(cls, params: Mapping[str, Any]) -> FollowerParams:
        """From the node's parameters: every follower.* key (the others are not the follower's). ValueError for an
        unknown or a missing one."""
        given = {k[len(PREFIX):]: v for k, v in params.items() if k.startswith(PREFIX)}
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(given) - set(names))
        missing = [n for n in names if n not in given]
        if unknown or missing:
            raise ValueError(f"follower parameters: unknown {[PREFIX + k for k in unknown]}, "
                             f"missing {[PREFIX + k for k in missing]}")
        return cls(**{k: float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                      for k, v in given.items()})

    @classmethod
    def load(cls, path: str | Path | None = None) -> FollowerParams:
        """The follower.* keys of config/motion_planner.yaml, with those of the ROS params file at `path` (if any)
        over them."""
        return cls.from_mapping(node_parameters(path))


def joint_error(q_ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """q_ref - q, wrapped to (-pi, pi] on the continuous joints (1, 3, 5, 7); q_ref one configuration or a row
    of them."""
    e = np.asarray(q_ref, float) - np.asarray(q, float)
    cont = np.array(rd.CONTINUOUS)
    e[..., cont] = (e[..., cont] + math.pi) % (2 * math.pi) - math.pi
    return e


class TrajectoryFollower:
    """Time-scaled tracking of one trajectory: call `update(q, dt)` per cycle, stream `command(q)`."""

    RUNNING, SETTLED, FAILED = "running", "settled", "failed"

    def __init__(self, trajectory: Trajectory, qdot_max: ArrayLike = rd.QDOT_MAX, params: FollowerParams | None = None
                 ) -> None:
        if len(trajectory) == 0:
            raise ValueError("cannot follow an empty trajectory")
        self.traj = trajectory
        self.qdot_max = np.asarray(qdot_max, float)
        self.p = params if params is not None else FollowerParams.load()  # config/motion_planner.yaml
        self.tau = 0.0  # reference time
        self.waited = 0.0  # s the reference has been waiting for the arm (reset when it moves on)
        self.rate = 1.0  # time-scaling rate s of the last update
        self.after_end = 0.0  # s since the reference ended
        self.within = 0.0  # s the arm has been within settle_tol of the last point (after the end)
        self.reason = ""

    @property
    def duration(self) -> float:
        """Length of the planned trajectory (s)."""
        return self.traj.duration

    @property
    def progress(self) -> float:
        """Fraction of the planned trajectory the reference has passed (0..1)."""
        return min(1.0, self.tau / self.duration) if self.duration > 0 else 1.0

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Planned position (interpolated) and velocity (held) at time t; after the end, the last point, 0."""
        tr = self.traj
        if t >= tr.duration:
            return tr.positions[-1], np.zeros(rd.N_JOINTS)
        k = int(np.clip(np.searchsorted(tr.times, t, side="right") - 1, 0, len(tr.times) - 1))
        return tr.positions[k] + tr.velocities[k] * (t - tr.times[k]), tr.velocities[k]

    def _error(self, q: ArrayLike) -> float:
        q = np.asarray(q, float)
        if q.shape != (rd.N_JOINTS,) or not np.all(np.isfinite(q)):
            raise ValueError(f"measured configuration must be 7 finite angles, got {q!r}")
        return float(np.max(np.abs(joint_error(self.reference(self.tau)[0], q))))

    def update(self, q: ArrayLike, dt: float) -> str:
        """Advance the reference by dt of wall time given the measured configuration; RUNNING, SETTLED or
        FAILED (see `reason`)."""
        err = self._error(q)
        if err > self.p.max_error:
            self.reason = f"tracking error {err:.3f} rad > max_error {self.p.max_error} rad at tau={self.tau:.2f} s"
            return self.FAILED
        if self.tau < self.duration:
            self.rate = min(1.0, max(0.0, (2.0 * self.p.lag_tol - err) / self.p.lag_tol))
            # after a gap longer than max_step (the command stream was late: the driver stopped the arm after its
            # watchdog), the reference goes on from where the arm could have followed it, not dt further
            self.tau = min(self.tau + self.rate * min(dt, self.p.max_step), self.duration)
            self.waited = 0.0 if self.rate >= 0.1 else self.waited + dt
            if self.waited > self.p.stall_timeout:
                self.reason = (f"stalled at tau={self.tau:.2f} s: error {err:.3f} rad > 2 lag_tol for "
                               f"{self.p.stall_timeout} s (is the arm blocked?)")
                return self.FAILED
        else:
            self.after_end += dt
        if self.tau >= self.duration:
            err = self._error(q)
            self.within = self.within + dt if err <= self.p.settle_tol else 0.0
            if self.within >= self.p.settle_dwell:
                return self.SETTLED
            if self.after_end > self.p.settle_timeout:
                if err <= self.p.settle_tol:  # within it now, never for settle_dwell (states far older): as before
                    return self.SETTLED
                self.reason = (f"did not settle within {self.p.settle_timeout} s: error {err:.4f} rad "
                               f"> settle_tol {self.p.settle_tol} rad")
                return self.FAILED
        return self.RUNNING

    def command(self, q: ArrayLike) -> np.ndarray:
        """Joint velocities (rad/s) to send now given the measured configuration q."""
        self._error(q)
        q_ref, v_ff = self.reference(self.tau)
        rate = self.rate if self.tau < self.duration else 0.0
        v = rate * v_ff + self.p.k_track * joint_error(q_ref, np.asarray(q, float))
        return np.clip(v, -self.qdot_max, self.qdot_max)
