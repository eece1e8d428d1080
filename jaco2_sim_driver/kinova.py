"""The simulator's fingers in Kinova's finger units (no rclpy): Kinova's turns, 0 open .. 6800 closed
(relocation_common.kinova, sources in docs/kinova.md), map linearly onto the simulated finger hinges, 0 open ..
FINGER_CLOSED (0.5 rad, the tips meet)."""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from relocation_common.kinova import FINGER_MAX_TURN

from .scene import FINGER_CLOSED


def turns_to_sim(turns: ArrayLike) -> np.ndarray:
    """Finger turns -> simulated finger hinge angles (rad), clamped to 0 .. 6800 turns."""
    t = np.clip(np.asarray(turns, float), 0.0, FINGER_MAX_TURN)
    return t / FINGER_MAX_TURN * FINGER_CLOSED


def sim_to_turns(q: ArrayLike) -> np.ndarray:
    """Simulated finger hinge angles (rad) -> finger turns; the inverse of `turns_to_sim` without the clamp."""
    return np.asarray(q, float) / FINGER_CLOSED * FINGER_MAX_TURN
