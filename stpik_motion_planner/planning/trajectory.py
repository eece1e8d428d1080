"""Joint trajectories ready to stream: positions and velocities over time, in the Q convention (rad, rad/s).

A trajectory is piecewise linear in position with piecewise-constant velocity: velocities[k] is the command held
over [times[k], times[k+1]) and positions[k+1] = positions[k] + velocities[k] * (times[k+1] - times[k]).
Streaming velocities[k] at the sample rate therefore reproduces the positions. The last velocity row is zero.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from relocation_common import robot_description as rd

STREAM_RATE = 100.0  # Hz, the rate of kinova's joint velocity commands


@dataclass
class Trajectory:
    """A joint trajectory ready to stream (see the module docstring for the sampling)."""

    times: np.ndarray  # (N,) s, from 0
    positions: np.ndarray  # (N, 7) rad, Q convention
    velocities: np.ndarray  # (N, 7) rad/s, velocities[k] held until times[k+1]; last row 0
    joint_names: tuple[str, ...] = rd.JOINT_NAMES
    phases: list[tuple[str, float]] = field(default_factory=list)  # (name, start time) e.g. approach, grasp

    @property
    def duration(self) -> float:
        """Length of the trajectory (s); 0 when empty."""
        return float(self.times[-1]) if len(self.times) else 0.0

    def __len__(self) -> int:
        return len(self.times)

    @classmethod
    def from_steps(cls, q: np.ndarray, qdot: np.ndarray, dt: float, phase: str = "") -> "Trajectory":
        """From IK steps: q is (N+1) x 7 at k*dt, qdot N x 7 held over each step."""
        n = len(q)
        vel = np.zeros((n, rd.N_JOINTS))
        vel[: n - 1] = qdot
        return cls(np.arange(n) * dt, np.array(q, float), vel, phases=[(phase, 0.0)] if phase else [])

    def resample(self, rate: float = STREAM_RATE) -> "Trajectory":
        """Samples at 1/rate: positions interpolated linearly, velocities the mean over each sample interval."""
        if len(self.times) < 2:
            return Trajectory(self.times.copy(), self.positions.copy(), self.velocities.copy(), self.joint_names,
                              list(self.phases))
        t = np.arange(0.0, self.duration + 1e-9, 1.0 / rate)
        if t[-1] < self.duration - 1e-9:
            t = np.append(t, self.duration)
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        pos = self.positions[k] + self.velocities[k] * (t - self.times[k])[:, None]
        pos[-1] = self.positions[-1]
        # the mean velocity over each sample interval: streaming it reproduces pos exactly, and as a mean of
        # velocities within the box of Table 7 it stays within that box
        vel = np.zeros_like(pos)
        vel[:-1] = np.diff(pos, axis=0) / np.diff(t)[:, None]
        return Trajectory(t, pos, vel, self.joint_names, list(self.phases))

    def then(self, other: "Trajectory") -> "Trajectory":
        """Concatenation (other starts where this one ends)."""
        if len(self.times) == 0:
            return other
        off = self.duration
        return Trajectory(np.concatenate([self.times, other.times[1:] + off]),
                          np.vstack([self.positions, other.positions[1:]]),
                          np.vstack([self.velocities[:-1], other.velocities]),
                          self.joint_names, self.phases + [(n, t + off) for n, t in other.phases])

    def back_from(self, q: ArrayLike) -> "Trajectory":
        """The way back: from the sample nearest to q (largest joint difference) to the start, reversed in time over
        the same samples (the same path, as collision-free as the way there, within the same velocity limits)."""
        if len(self.times) == 0:
            return Trajectory.empty()
        k = int(np.argmin(np.max(np.abs(self.positions - np.asarray(q, float)), axis=1)))
        pos = self.positions[: k + 1][::-1].copy()
        t = self.times[k] - self.times[: k + 1][::-1]
        vel = np.zeros_like(pos)
        if len(t) > 1:
            vel[:-1] = np.diff(pos, axis=0) / np.diff(t)[:, None]
        return Trajectory(t, pos, vel, self.joint_names, [("back", 0.0)])

    def from_sample(self, k: int) -> "Trajectory":
        """The rest from sample k on: the same samples and velocities, its times from 0."""
        return Trajectory(self.times[k:] - self.times[k], self.positions[k:].copy(), self.velocities[k:].copy(),
                          self.joint_names, [("on", 0.0)])

    @classmethod
    def empty(cls) -> "Trajectory":
        """A trajectory with no points."""
        return cls(np.zeros(0), np.zeros((0, rd.N_JOINTS)), np.zeros((0, rd.N_JOINTS)))
