"""The push (stpik_motion_planner/planning/push/) replayed in MuJoCo's physics: on generated "X beside T" layouts
(test/push_layouts.py; seeds fixed before any result: 0-3 by default, 4-11 with -m extended) the planner's push of
X out of T's lanes is carried out by execution.push.push (what the motion_planner node runs for a RelocateObject
goal with action "push") with the time-scaled follower on the simulator's core, every physics step watched. Asked
of each push: no contact of the arm or hand with anything but X, X upright at the end, X's simulated end pose within
END_TOL of the one the planner predicted, nothing else moved. The rate and each failure with its reason are printed;
a push with a wrong prediction (the predicted end moved by 2 END_TOL) is shown to fail the same check. On "X beside T,
B across" layouts (held_lane_layout, seeds fixed before any result) the push chosen opens a lane then free of every
other bottle before a shorter one that opens a lane B still holds. On "a box X beside T" layouts (box_beside_layout,
seeds 0-11 fixed before any result: 0-5 by default, 6-11 with -m extended) the box is slid on its face along a
face's normal, the same checks asked."""
from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest
import yaml
from push_layouts import beside_layout, box_beside_layout, held_lane_layout

from jaco2_sim_driver.sim import Jaco2Sim
from relocation_app.evaluation.scenes.jitter import jitter_scene
from relocation_common.feasibility import Label
from relocation_common.paths import config_file
from relocation_common.scenario import Scenario, parse_scenario
from stpik_motion_planner.execution.follower import TrajectoryFollower
from stpik_motion_planner.execution.push import push
from stpik_motion_planner.model.push import moved
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner
from stpik_motion_planner.planning.push import PushPlan
from stpik_motion_planner.planning.push.target import candidates, end_xy

DT = 0.01
PARAMS = dataclasses.replace(PlannerParams.load(), timeout=300.0, carry_timeout=300.0)
END_TOL = 0.010  # m between X's simulated and predicted end positions (on the board)
UPRIGHT = 0.995  # cos of X's tilt at the end
STILL = 0.005  # m any other object may move
ARM = ("upper_arm", "forearm", "wrist", "palm", "finger_sim_1", "finger_sim_2", "finger_sim_3")
DEFAULT_SEEDS = (0, 1, 2, 3)
EXTENDED_SEEDS = tuple(range(4, 12))
HELD_LANE_SEEDS = tuple(range(8))


class PushWatch:
    """relocation.Arm on the simulator's core (100 Hz commands from the follower), every physics step watched: the
    deepest contact of each pair of an arm geom and anything but the pushed object (which only the fingers and the
    palm may touch)."""

    def __init__(self, sim: Jaco2Sim, pushed: str) -> None:
        self.sim = sim
        m = sim.model
        self.name = lambda g: mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)
        self.arm = {m.geom(n).id for n in ARM}
        self.allowed = m.geom(f"{pushed}_geom").id
        self.hand = {m.geom(n).id for n in ARM if n.startswith("finger") or n == "palm"}
        self.unintended: dict[tuple[str, str], float] = {}
        self.phases: list[str] = []

    def step(self, n: int) -> None:
        d = self.sim.data
        for _ in range(n):
            self.sim.step(1)
            for k, (g1, g2) in enumerate(d.contact.geom.tolist()[:d.ncon]):
                if (g1 in self.arm) == (g2 in self.arm) or {g1, g2} <= self.hand | {self.allowed}:
                    continue  # arm-arm pairs are the self-collision check's; X is what the fingers and palm may touch
                key = tuple(sorted((self.name(g1), self.name(g2))))
                self.unintended[key] = min(self.unintended.get(key, 0.0), float(d.contact.dist[k]))

    # relocation.Arm: what execution.push.push drives
    def measured(self) -> np.ndarray:
        return self.sim.q

    def follow(self, traj, phase: str) -> None:
        self.phases.append(phase)
        f = TrajectoryFollower(traj)
        while (status := f.update(self.sim.q, DT)) == f.RUNNING:
            self.sim.set_velocity(f.command(self.sim.q))
            self.step(10)
        self.sim.stop()
        self.step(20)
        assert status == f.SETTLED, f"{phase}: {f.reason}"

    def gripper(self, action: str, phase: str) -> None:
        self.phases.append(phase)
        if action == "open":
            self.sim.gripper_open()
        else:
            assert action == "shut" and self.sim.gripper_close() is None, "the push's hand closed on something"
        self.step(300)

    def phase(self, phase: str) -> None:
        self.phases.append(phase)


def push_problems(sim: Jaco2Sim, watch: PushWatch, plan: PushPlan, start: dict[str, np.ndarray],
                  predicted: tuple[float, float, float]) -> list[str]:
    """What the simulated push did differently from the plan (empty: as predicted)."""
    pose = {p.id: p for p in sim.object_poses()}
    x = pose[plan.object_id]
    out = []
    off = math.dist(x.position[:2], predicted[:2])
    if off > END_TOL or abs(x.position[2] - predicted[2]) > 0.002:
        out.append(f"{plan.object_id} ended {off * 1000:.1f} mm from its predicted pose "
                   f"({np.round(x.position, 4).tolist()} against {np.round(predicted, 4).tolist()})")
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.array(x.quat_wxyz))
    if m[8] < UPRIGHT:
        out.append(f"{plan.object_id} tilted {math.degrees(math.acos(min(1.0, m[8]))):.0f} deg")
    for i, p in pose.items():
        if i != plan.object_id and np.linalg.norm(np.array(p.position) - start[i]) > STILL:
            out.append(f"{i} moved {np.linalg.norm(np.array(p.position) - start[i]) * 1000:.0f} mm")
    out += [f"contact {a} - {b} {d * 1000:+.1f} mm" for (a, b), d in sorted(watch.unintended.items())]
    return out


def pushed_in_mujoco(seed: int, wrong: float = 0.0, touched: str = "X", layout=beside_layout
                     ) -> tuple[str, list[str]]:
    """('planned' or 'refused: why', problems) of the push of X out of T's lanes on `layout`(seed), replayed in
    physics; `wrong` (m) moves the predicted end along the push (a wrong prediction), `touched` names the object the
    hand may touch (another than X: every touch of X is a contact), both for the check's own tests."""
    sc = layout(seed)
    planner = MotionPlanner(sc, PARAMS)
    ans, _ = planner.push_feasibility("X", "T", [])
    if ans.label == Label.UNFEASIBLE:
        assert ans.message
        return f"refused: {ans.message}", []
    sim = Jaco2Sim(sc)
    start = {p.id: np.array(p.position) for p in sim.object_poses()}
    watch = PushWatch(sim, touched)
    plan = push(planner, watch, "X", "T", [])  # what a RelocateObject goal with action "push" runs
    assert watch.phases == ["plan_push", "shut", "approach_push", "push", "retreat_push", "home_push", "open",
                            "pushed"], watch.phases
    watch.step(300)
    predicted = (plan.end[0] + wrong * math.cos(plan.yaw), plan.end[1] + wrong * math.sin(plan.yaw), plan.end[2])
    at = {p.id: np.array(p.position) for p in sim.object_poses()}["X"]
    moved, off = np.linalg.norm(at[:2] - start["X"][:2]), math.dist(at[:2], predicted[:2])
    return (f"planned: {ans.message}; X moved {moved * 1000:.1f} mm, {off * 1000:.1f} mm from the prediction",
            push_problems(sim, watch, plan, start, predicted))


def _report(seeds: tuple[int, ...]) -> None:
    rows = [(s, *pushed_in_mujoco(s)) for s in seeds]
    planned = [r for r in rows if r[1].startswith("planned")]
    ok = [r for r in planned if not r[2]]
    for s, what, problems in rows:
        print(f"seed {s}: {what}" + (f"; FAILED: {'; '.join(problems)}" if problems else ""))
    print(f"pushes planned {len(planned)}/{len(rows)}, as predicted in physics {len(ok)}/{len(planned)}")
    assert len(planned) >= len(rows) // 2, "the push planned on fewer than half the layouts"
    assert len(ok) == len(planned), [r for r in planned if r[2]]


def test_pushes_on_generated_layouts_end_where_predicted_in_mujoco():
    _report(DEFAULT_SEEDS)


def _box_report(seeds: range) -> None:
    """A box X beside T (box_beside_layout): every push planned ends as predicted in physics, upright, nothing else
    touched or moved; the rest are refused with a reason; at least one planned. The old planner refused every one
    ("X is not a cylinder")."""
    rows = [(s, *pushed_in_mujoco(s, layout=box_beside_layout)) for s in seeds]
    planned = [r for r in rows if r[1].startswith("planned")]
    for s, what, problems in rows:
        print(f"seed {s}: {what}" + (f"; FAILED: {'; '.join(problems)}" if problems else ""))
        assert what.startswith("planned") and "(a box slid on its face)" in what or what.startswith("refused: no push")
    print(f"box pushes planned {len(planned)}/{len(rows)}, as predicted in physics "
          f"{len([r for r in planned if not r[2]])}/{len(planned)}")
    assert planned and not [r for r in planned if r[2]], [r for r in planned if r[2]]


def test_box_pushes_on_generated_layouts_end_where_predicted_in_mujoco():
    _box_report(range(6))


@pytest.mark.extended
def test_box_pushes_on_more_generated_layouts_end_where_predicted_in_mujoco():
    _box_report(range(6, 12))


@pytest.mark.extended
def test_pushes_on_more_generated_layouts_end_where_predicted_in_mujoco():
    _report(EXTENDED_SEEDS)


def test_a_wrong_prediction_fails_the_physics_check():
    """The check can fail: the same push with its predicted end 2 END_TOL farther along the push is refused."""
    what, problems = pushed_in_mujoco(DEFAULT_SEEDS[0], wrong=2 * END_TOL)
    assert what.startswith("planned"), what
    assert any("from its predicted pose" in p for p in problems), problems


def test_a_touch_of_another_object_fails_the_physics_check():
    """The contact watch sees the hand's contacts: the same push, with T as the one object the hand may touch,
    fails on its contacts with X."""
    what, problems = pushed_in_mujoco(DEFAULT_SEEDS[0], touched="T")
    assert what.startswith("planned"), what
    assert any(p.startswith("contact") and "X_geom" in p and "finger_sim" in p for p in problems), problems


def test_a_push_in_the_back_row_plans_its_way_home():
    """scenario3_15 perturbed (seed 0, 12 mm): 'o14 needs T moved' at the back of the shelf. With the others gone,
    the push of o14 plans; its way home starts with the palm at STPIK's clearance over the board (a way home that
    asked 5 mm more refused every candidate: "no way home after the push")."""
    data = jitter_scene(yaml.safe_load(config_file("scenarios/scenario3_15.yaml").read_text()), 0.012, 0)
    planner = MotionPlanner(parse_scenario(data, data["name"]), PARAMS)
    others = [o.id for o in planner.scenario.objects if o.id not in ("o14", "T")]
    ans, plan = planner.push_feasibility("o14", "T", others)
    assert ans.label == Label.OBSTACLE and plan is not None, ans.message


def opened_lanes(sc: Scenario, yaw: float, distance: float) -> dict[str, frozenset[str]]:
    """The lanes of T a push of X by `distance` along `yaw` opens (X among their blockers before, not after, and no
    new blocker: the planner's lane screen, MotionPlanner.lane_blockers, on the scene before and with X moved) ->
    the bottles still blocking each after the push (empty: the lane free, T's side grasp with nothing relocated)."""
    before = {b.lane: b.objects for b in MotionPlanner(sc, PARAMS).lane_blockers()["T"]}
    x = sc.object("X")
    after = MotionPlanner(moved(sc, "X", *end_xy(x.x, x.y, yaw, distance)), PARAMS).lane_blockers()["T"]
    return {b.lane: b.objects for b in after
            if "X" in before.get(b.lane, frozenset()) and "X" not in b.objects and b.objects <= before[b.lane]}


def test_a_push_that_frees_a_lane_is_taken_before_a_shorter_one_into_a_held_lane():
    """held_lane_layout seeds 0-7 (fixed before any result). A layout counts where the shortest candidate push of X
    (least distance, then push.directions' order) opens only lanes of T another bottle still holds while a longer
    one opens a lane then free, and a push plans: there the push planned opens a free lane (T's side grasp needs no
    further relocation), and it ends in MuJoCo where predicted, touching nothing but X. The old order (least
    distance first) took the shortest. At least one layout counts."""
    counted = []
    for seed in HELD_LANE_SEEDS:
        sc = held_lane_layout(seed)
        planner = MotionPlanner(sc, PARAMS)
        cands = sorted(candidates(planner, "X", "T", frozenset())[0], key=lambda c: c[1])  # stable: directions next
        shortest = opened_lanes(sc, cands[0][0], cands[0][1]) if cands else {}
        free = next(((c[0], c[1]) for c in cands[1:] if frozenset() in opened_lanes(sc, c[0], c[1]).values()), None)
        print(f"seed {seed}: {len(cands)} candidates; the shortest {cands[0][:2] if cands else None} opens "
              f"{shortest}; the first that opens a free lane: {free}")
        if not (shortest and all(shortest.values()) and free):
            continue
        ans, plan = planner.push_feasibility("X", "T", [])
        if plan is None:  # no motion for any candidate: no choice to check
            print(f"  no push plans: {ans.message}")
            continue
        lanes = opened_lanes(sc, plan.yaw, plan.distance)
        counted.append(seed)
        print(f"  planned: {ans.message}; lanes opened {lanes}")
        assert lanes.get(plan.lane) == frozenset(), (seed, ans.message, lanes)
        assert plan.distance >= cands[0][1], (seed, ans.message)
        what, problems = pushed_in_mujoco(seed, layout=held_lane_layout)
        print(f"  in MuJoCo: {what}" + (f"; FAILED: {problems}" if problems else ""))
        assert what.startswith("planned") and not problems, (seed, what, problems)
    print(f"layouts where the shortest push opens a held lane and a longer one a free lane, a push planned: {counted}")
    assert counted, "no layout where the shortest push opens a held lane and a longer one a free one"
