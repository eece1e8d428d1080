"""The motion of a push and its answer (the package docstring, step 2): approach, push, retreat, way home, each
tracked by STPIK with the closed hand; `plan_push` over the candidates of target.py, `push_feasibility` the answer."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from relocation_common import robot_description as rd
from relocation_common.feasibility import FeasibilityAnswer, Label
from stpik_motion_planner.model.collision import (
    ArmGeometry,
    CollisionScene,
    HandProxy,
    ObstacleSet,
    closed_fingers,
)
from stpik_motion_planner.model.grasp import WorkspaceError, check_pose, pose_matrix, pose_roll
from stpik_motion_planner.model.push import PALM, SLIDE, contact_pose, kind, leading, moved
from stpik_motion_planner.planning.context import PlanningContext
from stpik_motion_planner.planning.home import joint_motion_clear, joint_valid, plan_joint, time_joint_path
from stpik_motion_planner.planning.pick import cartesian_path
from stpik_motion_planner.planning.push.target import candidates, end_xy, refusal
from stpik_motion_planner.planning.results import QueryStats, Segment
from stpik_motion_planner.planning.trajectory import Trajectory

LEAD_MARGIN = 0.01  # m the finger tips lead the rest of the closed hand along a push, at least


@dataclass
class PushPlan:
    """A planned push of `object_id` out of the lanes of `clear_for`: direction `yaw` (rad), `distance` (m), X's
    predicted end pose `end` (x, y, z of its base in the scene's frame, the robot base's, as ObjectState; a lying
    one's: of its centre, its yaw kept), the lane of C it opens, the motion's segments (approach, push, retreat,
    home; the gripper shut before the first, opened after the last), and its kind (model/push.kind: standing,
    slide, roll)."""

    object_id: str
    clear_for: str
    yaw: float
    distance: float
    end: tuple[float, float, float]
    lane: str
    segments: list[Segment]
    kind: str

    def trajectory(self) -> Trajectory:
        """The whole motion, home to home."""
        t = self.segments[0].trajectory
        for s in self.segments[1:]:
            t = t.then(s.trajectory)
        return t


def contact_height(ctx: PlanningContext, object_id: str) -> float:
    """m above the board where the leading finger tip touches: push.contact_height of a standing object's height (a
    lying one's axis height), no lower than the palm (below the tool axis by its radius) keeps STPIK's clearance and
    activation band over the board (the closed fingers' lowest point then stays higher above it)."""
    o = ctx.scenario.object(object_id)
    at = o.radius if o.lying else ctx.params.push.contact_height * o.height
    return max(at, PALM.radius + ctx.ceiling_clearance)


def hand_yaws(ctx: PlanningContext, object_id: str, yaw: float) -> list[tuple[float, float]]:
    """The hands tried for a push along `yaw`, (yaw, roll) each: the push's own yaw; for the slide of a lying
    cylinder, turned from it towards straight in (+x) by each of push.hand_turns: a sideways slide with the hand
    pointing into the shelf. A push to the right of straight in then goes to the hand's right, fingers 2 and 3
    leading. One to the left leads with finger 1 alone, at the tool axis' height (`tip_problem` says why a lying
    bottle of the shipped size is not pushed so), so it is tried again with the hand rolled half a turn about its
    axis (joint 7), fingers 2 and 3 leading to its left."""
    o = ctx.scenario.object(object_id)
    if kind(o, yaw) != SLIDE:
        return [(yaw, 0.0)]
    towards = 1.0 if yaw <= 0 else -1.0
    out = []
    for t in ctx.params.push.hand_turns:
        out.append((math.remainder(yaw + towards * t, 2 * math.pi), 0.0))
        if towards < 0 and t > 0:
            out.append((out[-1][0], math.pi))
    return out


def tip_problem(ctx: PlanningContext, object_id: str, contact: np.ndarray, yaw: float) -> str:
    """Why the closed hand at `contact` (x, y, z, hand yaw) cannot push `object_id` along `yaw` with its finger tips
    ('' if it can): the hinges or the palm would lead the tips (the hand turned too far from the push), or, for a
    lying cylinder or a box, every leading tip passes over its end cap, side or face (higher than its top less a
    tip's radius)."""
    lead, ahead = leading(yaw, float(contact[3]), pose_roll(contact))
    if ahead < LEAD_MARGIN:
        return f"the hand turned {abs(contact[3] - yaw):.2f} rad from the push leads with its side, not its tips"
    o = ctx.scenario.object(object_id)
    low = float(contact[2] + lead[:, 2].min()) - ctx.scenario.shelf.top_z
    top = 2 * o.radius if o.lying else o.height
    if (o.lying or o.shape == "box") and low > top - rd.FINGER_RADIUS:
        return (f"the leading finger tip, {low * 1000:.0f} mm over the board, would pass over {object_id} "
                f"({top * 1000:.0f} mm high)")
    return ""


def plan_motion(ctx: PlanningContext, object_id: str, removed: frozenset[str], yaw: float, distance: float,
                deadline: float, stats: QueryStats, hand_yaw: float | None = None, hand_roll: float = 0.0
                ) -> tuple[list[Segment], str]:
    """The push's motion for one candidate (the package docstring, step 2), the hand pointing along `hand_yaw`
    (default: the push's `yaw`), rolled `hand_roll` about its axis (`rolled_home`): (segments, '') or ([], why not)."""
    p, pp = ctx.params, ctx.params.push
    o = ctx.scenario.object(object_id)
    hand_yaw = yaw if hand_yaw is None else hand_yaw
    n = 6 if hand_roll else 4  # a horizontal hand: (x, y, z, yaw) poses, or (x, y, z, yaw, 0, hand_roll) rolled
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0, 0.0, 0.0, 0.0])[:n]
    h = np.array([math.cos(hand_yaw), math.sin(hand_yaw), 0.0, 0.0, 0.0, 0.0])[:n]
    contact = np.array(contact_pose(o, ctx.scenario.shelf.top_z, yaw, 0.0, contact_height(ctx, object_id),
                                    pp.contact_gap, hand_yaw, hand_roll)[:n])
    # the palm's bound holds for the tool axis whichever tip leads (finger 2 or 3 leads a push turned to -y: 22 mm
    # above the axis, which the leading tip's height alone would bring 22 mm lower, the palm into the board)
    contact[2] = max(contact[2], ctx.scenario.shelf.top_z + PALM.radius + ctx.ceiling_clearance)
    turned = hand_yaw != yaw or hand_roll
    why = tip_problem(ctx, object_id, contact, yaw) if turned or o.lying or o.shape == "box" else ""
    if why:
        return [], why
    # in along the hand's axis, the push along `yaw`, out along the hand's axis (back to `pre` when they are one)
    pre, end = contact - h * p.pre_grasp_distance, contact + u * (pp.contact_gap + distance)
    back = pre if hand_yaw == yaw else end - h * p.pre_grasp_distance
    try:
        for pose, where in ((pre, "pre-contact pose"), (contact, "contact pose"), (end, "end of the push"),
                            (back, "retreat")):
            check_pose(pose, f"push of {object_id}: {where}")
    except WorkspaceError as e:
        return [], str(e)
    fingers = closed_fingers()
    hand, arm = HandProxy(ctx.hand_margin, fingers=fingers), ArmGeometry(ctx.kin, fingers=fingers)
    obs = ctx.scene.obstacles(removed)
    skip = {n: frozenset([object_id]) for n in ("palm", *fingers)}  # the hand may touch X, never the board
    if hand.collides(*pose_matrix(pre), obs) or not hand.path_clear([pre, contact], obs, p.resolution, skip):
        return [], "no approach: the closed hand meets an object or a board before the contact pose"
    without = ctx.scene.obstacles(removed | {object_id})
    if not hand.path_clear([contact, end], without, p.resolution):
        return [], "the closed hand meets another object or a board along the push"
    ex, ey = end_xy(o.x, o.y, yaw, distance)
    after = CollisionScene(moved(ctx.scenario, object_id, ex, ey), (), ctx.lying, ctx.gone)
    after_obs = after.obstacles(removed)
    rng = ctx.question_rng("push", object_id, removed, yaw, distance, repr(pp), *((hand_roll,) if hand_roll else ()))
    q0, start, turn = rolled_home(ctx, hand_roll, obs, arm)
    if hand_roll and turn is None:
        return [], "the hand cannot be rolled at home: the turning hand meets something"
    last = "no approach"
    for attempt in range(p.max_attempts):
        path = cartesian_path(ctx, start, pre, obs, hand, p.rrt_max_checks, deadline, stats, attempt == 0, rng)
        if path is None:
            last = "no approach: no Cartesian path to the pre-contact pose"
            continue
        r1 = ctx.track(q0, path, obs, deadline, stats, arm=arm)
        if not r1.ok:
            last = f"no approach: STPIK rejected the path to the pre-contact pose: {r1.reason}"
            continue
        r2 = ctx.track(r1.q[-1], [pre, contact], obs, deadline, stats, skip, arm=arm, speed=p.stpik.approach_speed)
        if not r2.ok:
            return [], f"no approach: STPIK rejected the straight approach to the contact pose: {r2.reason}"
        r3 = ctx.track(r2.q[-1], [contact, end], without, deadline, stats, arm=arm, speed=pp.speed, ramp=p.carry_ramp)
        if not r3.ok:
            return [], f"STPIK rejected the push: {r3.reason}"
        r4 = ctx.track(r3.q[-1], [end, back], after_obs, deadline, stats, skip, arm=arm,
                       speed=p.stpik.approach_speed, ramp=p.carry_ramp)
        if not r4.ok:
            return [], f"STPIK rejected the retreat: {r4.reason}"
        home = way_home(ctx, r4.q[-1], ([rd.Q_HOME] if hand_roll else []) + list(r1.q), after_obs, arm, deadline, rng)
        if home is None:
            return [], "no way home after the push"
        approach = Trajectory.from_steps(r1.q, r1.qdot, r1.dt, "to_pre_contact")
        return [Segment("approach", (approach if turn is None else turn.then(approach)).then(
                    Trajectory.from_steps(r2.q, r2.qdot, r2.dt, "approach")).resample(), None),
                Segment("push", Trajectory.from_steps(r3.q, r3.qdot, r3.dt, "push").resample(), None),
                Segment("retreat", Trajectory.from_steps(r4.q, r4.qdot, r4.dt, "retreat").resample(), None),
                Segment("home", home, "open")], ""
    return [], last


def rolled_home(ctx: PlanningContext, hand_roll: float, obs: ObstacleSet, arm: ArmGeometry
                ) -> tuple[np.ndarray, np.ndarray, Trajectory | None]:
    """(the configuration the approach starts from, its tool pose, the motion there from home): home itself (no
    motion: None) for an unrolled hand; for a hand rolled half a turn, home with joint 7 turned by pi (the tool
    turns about its own axis: the arm's other links stay still), checked clear at home (None when it is not)."""
    if not hand_roll:
        return rd.Q_HOME, np.asarray(ctx.home, float), None
    q = rd.Q_HOME.copy()
    q[6] += hand_roll
    start = np.array([*ctx.home[:4], 0.0, hand_roll])
    if not joint_motion_clear(ctx, rd.Q_HOME, q, obs, 0.0, arm):
        return q, start, None
    return q, start, time_joint_path([rd.Q_HOME, q], 0.9 * rd.QDOT_MAX, ctx.params.stpik.dt)


def way_home(ctx: PlanningContext, q: np.ndarray, out: list[np.ndarray], obs: ObstacleSet, arm: ArmGeometry,
             deadline: float, rng: np.random.Generator | None) -> Trajectory | None:
    """From the pre-contact pose home, the closed hand's capsules checked at STPIK's clearance: back along the tracked
    way there (`out`, home first; a rolled hand turns back at home last) when that is still clear with the object at
    its end pose (every other IK step), else joint-space RRT-Connect."""
    # no margin over STPIK's clearance: the palm ends the push at that bound over the board (the contact height)
    if joint_motion_clear(ctx, q, out[-1], obs, 0.0, arm) and all(joint_valid(ctx, x, obs, arm) for x in out[::2]):
        return time_joint_path([q] + out[::-1], 0.9 * rd.QDOT_MAX, ctx.params.stpik.dt).resample()
    traj = plan_joint(ctx, q, rd.Q_HOME, obs, 4 * ctx.params.rrt_max_checks, deadline, 0.0, rng, arm)
    return None if traj is None else traj.resample()


def plan_push(ctx: PlanningContext, object_id: str, clear_for: str, removed: Iterable[str], deadline: float,
              stats: QueryStats) -> tuple[PushPlan | None, int, str]:
    """(the push, or None; attempts; the message: how, or why not): the module docstring."""
    removed = ctx.check_question(object_id, removed)
    if clear_for == object_id:
        raise ValueError(f"a push of {object_id!r} clears the lanes of another object, not its own")
    ctx.check_question(clear_for, removed)
    why = refusal(ctx, object_id, clear_for, removed)
    if why:
        return None, 0, why
    cands, why = candidates(ctx, object_id, clear_for, removed)
    if not cands:
        return None, 0, why
    last, n = "", 0
    for yaw, d, lane, held in cands:
        n += 1
        for hand_yaw, hand_roll in hand_yaws(ctx, object_id, yaw):
            segments, why = plan_motion(ctx, object_id, removed, yaw, d, deadline, stats, hand_yaw, hand_roll)
            if segments:
                break
        if segments:
            o = ctx.scenario.object(object_id)
            end = (*end_xy(o.x, o.y, yaw, d), ctx.scenario.shelf.top_z + (o.radius if o.lying else 0.0))
            then = f"still held by {', '.join(sorted(held))}" if held else "then free"
            turned = f", the hand at yaw {hand_yaw:+.2f}" if hand_yaw != yaw else ""
            turned += ", rolled half a turn" if hand_roll else ""
            how = f" ({kind(o, yaw)} of a lying cylinder{turned})" if o.lying else \
                " (a box slid on its face)" if o.shape == "box" else ""
            return PushPlan(object_id, clear_for, yaw, d, end, lane, segments, kind(o, yaw)), n, (
                f"push {object_id} {d * 1000:.0f} mm at yaw {yaw:+.2f}: opens {clear_for}'s lane {lane}, {then}{how}")
        last = f"yaw {yaw:+.2f}, {d * 1000:.0f} mm: {why}"
    return None, n, f"no push of {object_id} plans ({n} candidates opening {clear_for}'s lanes); last: {last}"


def push_feasibility(ctx: PlanningContext, object_id: str, clear_for: str, removed: Iterable[str] = frozenset(),
                     timeout: float | None = None) -> tuple[FeasibilityAnswer, PushPlan | None]:
    """The feasibility answer of a push (g_O: an action on an obstacle, never the retrieval; g_U with the reason)
    with its plan. Errors as pick.feasibility."""
    t0 = time.perf_counter()
    budget = ctx.params.timeout if timeout is None or timeout <= 0 else float(timeout)
    stats = QueryStats()
    ctx.last_stats = stats
    plan, attempts, msg = plan_push(ctx, object_id, clear_for, removed, t0 + budget, stats)
    dt = time.perf_counter() - t0
    if plan is None:
        return FeasibilityAnswer(Label.UNFEASIBLE, dt, attempts, msg), None
    return FeasibilityAnswer(Label.OBSTACLE, dt, attempts, msg, plan.trajectory(), near=None), plan
