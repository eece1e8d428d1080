"""Kinova's units and conventions for a Jaco2 (j2s7s300) behind kinova-ros's driver, shared by the simulated driver
and the motion planner (no rclpy). Sources, file by file: docs/kinova.md.

- Joint angles: Kinova's physical angles Q, the project's convention; kinova-ros publishes them in degrees on
  `out/joint_angles` and in radians on `out/joint_state` (kinova_arm.cpp, publishJointAngles).
- Joint velocity commands on `in/joint_velocity`: degrees per second (kinova_comm.cpp, setJointVelocities), to be
  streamed at 100 Hz (kinova-ros README, "Note on publish frequency").
- Fingers: actuator "turns", 0 fully open to about 6800 fully closed (kinova-ros README, "Finger position control";
  kinova_demo/nodes/kinova_demo/fingers_action_client.py: finger_maxTurn = 6800). In `out/joint_state` a finger
  is the angle turns * 80/6800 degrees (kinova_arm.cpp: finger_conv_ratio_ = 80.0 / 6800.0), fully closed = 80 deg
  = 1.396 rad.
- Fingers action `fingers_action/finger_positions` (kinova_fingers_action.cpp): succeeded when every finger is
  within `tolerance` turns of the goal (default 6400 * 0.01 = 64); aborted, with the positions reached, when the
  fingers stall: no finger moved more than `stall_threshold` turns (default 1) for `stall_interval_seconds`
  (default 0.5 s), i.e. they closed on an object.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

FINGER_MAX_TURN = 6800.0                    # turns: fully closed
FINGER_DEG_PER_TURN = 80.0 / 6800.0         # kinova_arm.cpp finger_conv_ratio_ (Jaco v2 fingers)
FINGER_JOINT_CLOSED = math.radians(FINGER_MAX_TURN * FINGER_DEG_PER_TURN)  # 1.396 rad in joint states
FINGER_TOLERANCE = 6400.0 * 0.01            # turns, kinova_fingers_action.cpp default tolerance
STALL_THRESHOLD = 1.0                       # turns, kinova_fingers_action.cpp default
STALL_INTERVAL = 0.5                        # s, kinova_fingers_action.cpp default


def turns_to_joint(turns: ArrayLike) -> np.ndarray:
    """Finger turns -> the finger joint angle of Kinova's joint states and URDF (rad; 0 open, 1.396 closed)."""
    return np.radians(np.asarray(turns, float) * FINGER_DEG_PER_TURN)


def joint_to_turns(rad: ArrayLike) -> np.ndarray:
    """Finger joint angle (rad) -> Kinova finger turns; the inverse of `turns_to_joint`."""
    return np.degrees(np.asarray(rad, float)) / FINGER_DEG_PER_TURN


class FingerMonitor:
    """When a finger motion is over, as kinova_fingers_action.cpp decides it: REACHED when every finger is within
    `tolerance` turns of the goal, STALLED when no finger moved more than `stall_threshold` turns for
    `stall_interval` seconds (of any clock: the simulator uses simulated time, the planner wall time)."""

    MOVING, REACHED, STALLED = "moving", "reached", "stalled"

    def __init__(self, goal: ArrayLike, t0: float, positions: ArrayLike, tolerance: float = FINGER_TOLERANCE,
                 stall_threshold: float = STALL_THRESHOLD, stall_interval: float = STALL_INTERVAL):
        self.goal = np.asarray(goal, float)
        self.tolerance, self.stall_threshold, self.stall_interval = tolerance, stall_threshold, stall_interval
        self._ref, self._ref_t = np.asarray(positions, float).copy(), t0

    def update(self, t: float, positions: ArrayLike) -> str:
        """REACHED, STALLED or MOVING for the finger `positions` (turns) at time `t` (s)."""
        p = np.asarray(positions, float)
        if np.all(np.abs(p - self.goal) <= self.tolerance):
            return self.REACHED
        if np.any(np.abs(p - self._ref) > self.stall_threshold):
            self._ref, self._ref_t = p.copy(), t
        elif t - self._ref_t > self.stall_interval:
            return self.STALLED
        return self.MOVING
