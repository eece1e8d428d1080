"""OMPL's RRT-Connect seeded per solve (stpik_motion_planner/planning/rrt.py, docs/motion_planner.md "Determinism"):
with a
seed, the path (OMPL's simplification included) is a function of the seed and the problem, whatever OMPL sampled
before in this process and whichever thread asks."""
from __future__ import annotations

import threading
import time

import numpy as np

from stpik_motion_planner.planning.rrt import JointRRT


def _valid(q: np.ndarray) -> bool:
    """A wall across the middle of the box with a gap at the top: RRT-Connect must sample to get round it."""
    return not (0.4 < q[0] < 0.6 and q[1] < 0.7)


def _plan(seed: int | None) -> bytes:
    rrt = JointRRT([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], resolution=0.01, simplify_checks=100)
    path = rrt.plan(np.array([0.1, 0.1, 0.5]), np.array([0.9, 0.1, 0.5]), _valid, 20000, time.perf_counter() + 60.0,
                    seed)
    assert path is not None
    return np.array(path).tobytes()


def test_the_same_seed_gives_the_same_path_after_other_solves_and_in_another_thread():
    first = _plan(11)
    _plan(None)  # OMPL's process-wide sequence moves on
    _plan(12)
    assert _plan(11) == first
    assert _plan(12) != first  # the seed matters
    out: dict[int, bytes] = {}
    threads = [threading.Thread(target=lambda k=k: out.__setitem__(k, _plan(11 if k % 2 else 12))) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert out[1] == out[3] == first
    assert out[0] == out[2] == _plan(12)
