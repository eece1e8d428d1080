"""The push of a cylinder lying flat (stpik_motion_planner/planning/push/: slid along its axis, or rolled across it)
replayed in MuJoCo's physics as test_push.py replays the push of a standing one: on generated "X lying in T's lanes"
layouts on paper_experiment_10's shelf (test/push_layouts.lying_layout; seeds fixed before any result: 0-7) the
planner's push of X out of T's lanes is carried out by execution.push.push with the time-scaled follower on the
simulator's core, every physics step watched. Asked of each push: no contact of the arm or hand with anything but X,
X still lying flat at the end, its centre within END_TOL of the predicted one and its axis within YAW_TOL of its yaw
(kept), nothing else moved. A roll (push.roll) is refused with its reason (docs/bench/push.md: it does not end where
predicted)."""
from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
from push_layouts import lying_layout
from test_push import END_TOL, PARAMS, STILL, PushWatch

from jaco2_sim_driver.sim import Jaco2Sim
from relocation_common.feasibility import Label
from relocation_common.shelf_object import half_turn
from stpik_motion_planner.execution.push import push
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

YAW_TOL = 0.10  # rad between X's simulated axis and its yaw, kept by the push
FLAT = 0.05  # |cos| of X's axis tilt from the horizontal at the end, at most (about 3 deg)
SEEDS = tuple(range(8))


def lying_pushed_in_mujoco(seed: int, params: PlannerParams = PARAMS) -> tuple[str, list[str], dict[str, float]]:
    """('planned: how' or 'refused: why', problems, {'off': m, 'yaw': rad, 'moved': m}) of the push of the lying X
    out of T's lanes on lying_layout(seed), planned with `params` and replayed in physics."""
    sc = lying_layout(seed)
    planner = MotionPlanner(sc, params)
    ans, _ = planner.push_feasibility("X", "T", [])
    if ans.label == Label.UNFEASIBLE:
        assert ans.message
        return f"refused: {ans.message}", [], {}
    sim = Jaco2Sim(sc)
    start = {p.id: np.array(p.position) for p in sim.object_poses()}
    watch = PushWatch(sim, "X")
    plan = push(planner, watch, "X", "T", [])
    watch.step(1000)  # 1 s more: a rolling X goes on
    x = sc.object("X")
    pose = {p.id: p for p in sim.object_poses()}
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.array(pose["X"].quat_wxyz))
    axis = rot.reshape(3, 3)[:, 2]
    centre = np.array(pose["X"].position) + axis * x.height / 2
    off = math.dist(centre[:2], plan.end[:2])
    dyaw = abs(half_turn(math.atan2(axis[1], axis[0]) - x.yaw))
    got = {"off": off, "yaw": dyaw, "moved": math.dist(centre[:2], (x.x, x.y))}
    out = []
    if off > END_TOL or abs(centre[2] - plan.end[2]) > 0.002:
        out.append(f"X ended {off * 1000:.1f} mm from its predicted centre ({np.round(centre, 4).tolist()} against "
                   f"{np.round(plan.end, 4).tolist()})")
    if abs(axis[2]) > FLAT:
        out.append(f"X no longer lies flat (axis z {axis[2]:+.2f})")
    if dyaw > YAW_TOL:
        out.append(f"X turned {dyaw:.2f} rad")
    for i, p in pose.items():
        if i != "X" and np.linalg.norm(np.array(p.position) - start[i]) > STILL:
            out.append(f"{i} moved {np.linalg.norm(np.array(p.position) - start[i]) * 1000:.0f} mm")
    out += [f"contact {a} - {b} {d * 1000:+.1f} mm" for (a, b), d in sorted(watch.unintended.items())]
    return f"planned: {ans.message}", out, got


def kind_params(slide: bool, roll: bool) -> PlannerParams:
    """PARAMS with the lying push kinds set."""
    return dataclasses.replace(PARAMS, push=dataclasses.replace(PARAMS.push, slide=slide, roll=roll))
