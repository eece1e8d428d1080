"""The straight approach of a grasp lane as STPIK drives it (Eq. 10, task 3): a lane whose hand is squeezed between
obstacles nearer than STPIK's activation distance is skipped before its path is planned.

The grasp screen (planning/pick.py, candidates) lets a lane through when the hand proxy, inflated by STPIK's bound
stpik.clearance, is clear along the straight approach pre-grasp -> grasp. STPIK itself activates an obstacle task when
a step would bring an arm capsule closer than stpik.clearance + stpik.act to an obstacle, and then holds that
distance. An obstacle within that band on one side only, the hand passes it shifted away (the tool may leave the path
by stpik.track_tol). Obstacles within it at once on both sides of the approach (left and right of its vertical plane,
at one pose along it) hold the hand from either side: STPIK stops on the approach, 30 mm short, on every attempt,
after the path to the pre-grasp was planned (RRT-Connect) and tracked. `squeezed_approach` names them; those
obstacles are not removed in the question, so the lane is as narrow whatever else is removed.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from stpik_motion_planner.model.collision import HandProxy, ObstacleSet, Skip
from stpik_motion_planner.model.grasp import Grasp, pose_matrix


@functools.lru_cache(maxsize=8)
def _proxy(margin: float) -> HandProxy:
    """The hand proxy inflated by `margin` (m), built once per margin."""
    return HandProxy(margin)


def side(g: Grasp, lo: np.ndarray, hi: np.ndarray) -> int:
    """+1 if the box (lo, hi) lies wholly left of the vertical plane of the approach of `g` (through the grasp, along
    its yaw), -1 wholly right, 0 across it (a board above or below, an obstacle straight ahead)."""
    c, s = math.cos(g.yaw), math.sin(g.yaw)
    lateral = [-s * (x - g.grasp[0]) + c * (y - g.grasp[1]) for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]
    return 1 if min(lateral) > 0 else -1 if max(lateral) < 0 else 0


def squeezed_approach(g: Grasp, obs: ObstacleSet, skip: Skip, band: float, resolution: float, short: float) -> str:
    """'' unless the hand proxy inflated by STPIK's activation distance `band` (stpik.clearance + stpik.act) meets,
    at one pose of the straight approach of `g` (sampled every `resolution` m from the pre-grasp to `short` m before
    the grasp: STPIK accepts the grasp within stpik.final_tol_pos), obstacles on both sides of it (what the hand may
    touch, `skip`, left out as in pick.candidates); then why the lane is skipped, naming them."""
    pre, grasp = np.asarray(g.pre_grasp, float), np.asarray(g.grasp, float)
    length = float(np.linalg.norm(grasp[:3] - pre[:3]))
    end = grasp + (pre - grasp) * min(1.0, short / length) if length > 0 else grasp
    n = max(1, math.ceil(float(np.linalg.norm(end[:3] - pre[:3])) / resolution))
    proxy = _proxy(band)
    for k in range(n + 1):
        hits = [obs.items[i] for i in proxy.hits(*pose_matrix(pre + (end - pre) * k / n), obs, skip)]
        if {1, -1} <= {side(g, o.lo, o.hi) for o in hits}:
            names = ", ".join(sorted(o.name for o in hits))
            return (f"the approach at yaw {g.yaw:+.2f} passes between {names}, nearer on both sides than STPIK's "
                    f"activation distance ({band * 1000:.0f} mm, stpik.clearance + stpik.act): lane skipped")
    return ""
