"""The push of a cylinder lying flat (stpik_motion_planner/planning/push/: slid along its axis, or rolled across it)
in MuJoCo's physics, as test_push.py checks the push of a standing one (docs/bench/push.md). `lying_pushed_in_mujoco`:
the planner's push of X out of T's lanes on generated "X lying in T's lanes" layouts (push_layouts.lying_layout,
diagonal_layout, across_layout; paper_experiment_10's shelf), carried out by execution.push.push with the
time-scaled follower on the simulator's core, every physics step watched; `kind_in_mujoco`: one kind's motion alone,
whether or not it opens a lane. Asked: no contact of the arm or hand with anything but X, X still lying flat, its
centre within END_TOL of the predicted one and its axis within YAW_TOL of its yaw (kept), nothing else moved. The
slide passes (the bottles' rolling friction stops X where the hand leaves it), sideways too, the hand pointing into
the shelf (push.hand_turns); the roll wedges the hand and is off. Seeds fixed before any result."""
from __future__ import annotations

import dataclasses
import math
import time

import mujoco
import numpy as np
from push_layouts import across_layout, diagonal_layout, lying_layout
from test_push import END_TOL, PARAMS, STILL, PushWatch

from jaco2_sim_driver.sim import Jaco2Sim
from relocation_common.feasibility import Label
from relocation_common.scenario import Scenario
from relocation_common.shelf_object import half_turn
from stpik_motion_planner.execution.push import push
from stpik_motion_planner.model.push import kind
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.push import PushPlan
from stpik_motion_planner.planning.push.motion import plan_motion
from stpik_motion_planner.planning.push.target import end_xy
from stpik_motion_planner.planning.results import QueryStats

YAW_TOL = 0.10  # rad between X's simulated axis and its yaw, kept by the push
FLAT = 0.05  # |cos| of X's axis tilt from the horizontal at the end, at most (about 3 deg)
SEEDS = tuple(range(8))


def lying_pushed_in_mujoco(seed: int, params: PlannerParams = PARAMS, layout=lying_layout
                           ) -> tuple[str, list[str], dict[str, float]]:
    """('planned: how' or 'refused: why', problems, {'off': m, 'yaw': rad, 'moved': m}) of the push of the lying X
    out of T's lanes on `layout`(seed), planned with `params` and replayed in physics."""
    sc = layout(seed)
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
    return f"planned: {ans.message}", *_checked(sc, sim, watch, plan, start)


def _checked(sc: Scenario, sim: Jaco2Sim, watch: PushWatch, plan: PushPlan, start: dict[str, np.ndarray]
             ) -> tuple[list[str], dict[str, float]]:
    """(what the simulated push of the lying X did differently from `plan`, {'off': its centre from the predicted
    one (m), 'yaw': its axis from its yaw before (rad), 'moved': its centre from where it lay (m)})."""
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
    return out, got


def kind_params(slide: bool, roll: bool) -> PlannerParams:
    """PARAMS with the lying push kinds set."""
    return dataclasses.replace(PARAMS, push=dataclasses.replace(PARAMS.push, slide=slide, roll=roll))


def kind_in_mujoco(seed: int, which: str, distance: float, alone: bool = False
                   ) -> tuple[str, list[str], dict[str, float]]:
    """The physics of one push kind alone, whether or not it opens a lane: on diagonal_layout(seed) (`alone`: X only,
    T moved to the far back corner), the lying X pushed `distance` along its axis (which 'slide') or across it
    ('roll'), the direction of the two with the larger component towards the back (+x); the motion planned as the
    planner's (motion.plan_motion: approach, push, retreat, home with the closed hand) and replayed in physics.
    ('planned ...' or 'no motion: why' or 'stalled: why', problems, numbers as lying_pushed_in_mujoco's, with
    'push_off' and 'push_yaw': X's centre from its predicted end and its axis from its yaw when the push ended)."""
    sc = diagonal_layout(seed)
    x = sc.object("X")
    if alone:
        t = dataclasses.replace(sc.object("T"), x=0.93, y=-0.3 if x.y > 0 else 0.3)
        sc = dataclasses.replace(sc, objects=(x, t), _by_id={})
    planner = MotionPlanner(sc, PARAMS)
    yaw = x.yaw + (0.0 if which == "slide" else math.pi / 2)
    yaw = math.remainder(yaw if math.cos(yaw) >= 0 else yaw + math.pi, 2 * math.pi)
    assert kind(x, yaw) == which
    segs, why = plan_motion(planner, "X", frozenset(), yaw, distance, time.perf_counter() + 120.0, QueryStats())
    if not segs:
        return f"no motion: {why}", [], {}
    end = (*end_xy(x.x, x.y, yaw, distance), sc.shelf.top_z + x.radius)
    plan = PushPlan("X", "T", yaw, distance, end, "", segs, which)
    sim = Jaco2Sim(sc)
    start = {p.id: np.array(p.position) for p in sim.object_poses()}
    watch = PushWatch(sim, "X")
    watch.gripper("shut", "shut")  # as execution.push.push: shut, each motion, open
    at_push: dict[str, float] = {}
    try:
        for seg in plan.segments:
            watch.follow(seg.trajectory, seg.name)
            if seg.name == "push":
                at_push = {f"push_{k}": v for k, v in _checked(sc, sim, watch, plan, start)[1].items()}
    except AssertionError as e:
        return f"stalled: {e}", [], _checked(sc, sim, watch, plan, start)[1]
    watch.gripper("open", "open")
    watch.step(1000)
    problems, got = _checked(sc, sim, watch, plan, start)
    return f"planned {which} {distance * 1000:.0f} mm at yaw {yaw:+.2f}", problems, {**got, **at_push}


def test_a_lying_push_is_refused_with_its_reason():
    """With push.slide and push.roll off, the push of a lying X is refused with the reason of each; the old planner
    said only that the push slides a standing cylinder."""
    ans, plan = MotionPlanner(lying_layout(0), kind_params(False, False)).push_feasibility("X", "T", [])
    assert ans.label == Label.UNFEASIBLE and plan is None
    assert "X lies (push.slide, push.roll off: a slid one rolls on" in ans.message, ans.message


def test_a_slide_ends_where_predicted_and_stays_there_in_mujoco():
    """diagonal_layout seeds 0, 1 (fixed before any result): the slide of the lying X along its axis by 60 mm, the
    closed hand against its end cap. When the push ends, and 1 s after the hand is home, X is within END_TOL of its
    predicted centre and its axis within YAW_TOL of its yaw; no contact but X's. Without the bottles' rolling
    friction (condim 4) X rolled on once the hand retreated, 10-53 mm."""
    for seed in (0, 1):
        what, problems, got = kind_in_mujoco(seed, "slide", 0.06)
        print(f"seed {seed}: {what}; {({k: round(v, 4) for k, v in got.items()})}; {problems}")
        assert what.startswith("planned"), what
        assert got["push_off"] <= END_TOL and got["push_yaw"] <= YAW_TOL, got
        assert got["off"] <= END_TOL and got["yaw"] <= YAW_TOL and not problems, (got, problems)


def test_a_bottle_lying_across_the_shelf_is_slid_sideways_in_mujoco():
    """across_layout seeds 0-15 (fixed before any result): X lying across the shelf in front of T, 0.85-1.55 rad
    from pointing in, so no grasp takes it under the 0.26 m board. Its push out of T's lanes is planned with the
    shipped settings; every one planned (a slide along X's axis, sideways, the hand pointing into the shelf) is
    replayed in physics and must end within END_TOL of its prediction, lying, with no contact but X's. The others
    are refused with a reason (a direction opening a lane would leave the shelf or meet a bottle, or the hand's
    poses are out of reach). One of those planned goes to the hand's left with the hand rolled half a turn (fingers
    2 and 3 leading; finger 1 alone would pass over X). The old planner refused all 16 ("push.slide, push.roll
    off"); the one before the rolled hand planned 2, both to the hand's right."""
    planned, refused, rolled = [], [], []
    for seed in range(16):
        what, problems, got = lying_pushed_in_mujoco(seed, PARAMS, across_layout)
        print(f"seed {seed}: {what}; {({k: round(v, 4) for k, v in got.items()})}; {problems}")
        (planned if what.startswith("planned") else refused).append(seed)
        assert not problems, (seed, what, problems)
        if what.startswith("planned"):
            assert "slide of a lying cylinder" in what, what
            rolled += ["rolled half a turn" in what]
        else:
            assert what.startswith("refused: no push"), what
    print(f"planned and executed as predicted: {len(planned)}/16 {planned}; refused: {refused}")
    assert len(planned) >= 3 and any(rolled), (planned, rolled, refused)


def test_a_roll_wedges_the_hand_in_mujoco():
    """diagonal_layout seed 0 with X alone: the roll of the lying X across its axis by 60 mm. The palm's bound over
    the board puts the leading tips above X's axis: the hand wedges on its side and the push stalls short, the
    reason push.roll is off."""
    what, _, got = kind_in_mujoco(0, "roll", 0.06, alone=True)
    print(what, got)
    assert what.startswith("stalled: push: did not settle"), what
    assert got["off"] > END_TOL, got
