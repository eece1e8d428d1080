"""The grasp from above of a lying cylinder (stpik_motion_planner.model.grasp: `grasp_from_above`, `lying_pitch`,
`stand_up_poses`): refused with the headroom it needs under the shipped shelf's board above; on a shelf with room,
relocated standing to a slot, replayed in MuJoCo by the independent checker (test/motion_checker.py: the simulator's
world, the bottle attached to the hand at the pose it had when the pick ended) and executed in MuJoCo's physics
(relocation.relocate on the simulator's core: the fingers close on the lying bottle and carry it).

The lying bottles are generated: one in the front row of a shelf with 0.48 m of headroom, a standing bottle beside
it and the target behind it, its axis's yaw and its place drawn from seeds fixed before any result (none dropped; a
bottle out of the arm's reach for a hand from above is answered "no grasp: " with why). Before, every lying
cylinder was answered "no grasp: <id> is lying on its side: the side grasp takes standing objects only" and stayed
an obstacle for good: the target lying could never be retrieved, one lying in its lanes never cleared.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from motion_checker import MotionChecker, Report, replay_relocation
from test_along_axis_grasp import lying_on_slot
from test_execution import carried_to_slot

from qtree_task_planner.problem import ActionCosts, RelocationProblem
from relocation_common.feasibility import NO_GRASP, SIDE_GRASP, TOP_GRASP, Label
from relocation_common.scenario import Scenario, load_scenario, parse_scenario
from stpik_motion_planner.execution.relocation import RelocationPlan, plan_relocation
from stpik_motion_planner.model.grasp import FINGER_FLOOR
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

# wall-clock safety nets of 300 s (answers must not depend on machine load); the work budgets are the planner's
PARAMS = dataclasses.replace(PlannerParams.load(), timeout=300.0, carry_timeout=300.0)
ARM_CLEARANCE = PARAMS.stpik.clearance - 0.002  # the planner's bounds less the interpolation between IK samples
FINGER_CLEARANCE = FINGER_FLOOR - 0.002  # the fingers over the board the bottle lies on (motion_checker: min_floor)
CARRIED_CLEARANCE = PARAMS.carried_clearance - 0.002
SHELF = {"x_front": 0.62, "depth": 0.36, "width": 0.8, "board_thickness": 0.02, "top_z": 0.02,
         "ceiling_z": 0.50, "bottom_z": -0.18}
MARKER = {"id": 7, "size": 0.07, "position": [0.625, -0.345, 0.09], "rpy": [1.5708, 0, -1.5708]}
SEEDS = tuple(range(12))  # fixed before any result, none dropped
PLACE_TOL = 0.006  # m: the bottle's base centre from its slot (STPIK's final tolerance 4 mm, the grasp's yaw error)
UPRIGHT = math.cos(math.radians(5))  # the placed bottle's axis within 5 deg of the vertical


def lying_scene(bottle: dict, seed: int | None = None) -> Scenario:
    """The lying bottle L (its axis's `yaw`, `xy` its centre), a standing bottle b1 0.15 m to its left and the
    target T behind it, on a shelf with 0.48 m of headroom."""
    x, y = bottle["xy"]
    objects = [{"id": "L", "weight": 0.3, "lying": True, **bottle},
               {"id": "b1", "weight": 0.5, "xy": [x, y + 0.15]},
               {"id": "T", "weight": 0.5, "xy": [max(x + 0.14, 0.84), y]}]
    return parse_scenario({"shelf": SHELF, "objects": objects, "target": "T", "marker": MARKER, "slots": "auto",
                           "name": f"lying_{seed}"})


def drawn_bottle(seed: int) -> dict:
    """A 0.16 m bottle lying at any yaw in the front row: its footprint 5-45 mm behind the shelf's front edge."""
    rng = np.random.default_rng(seed)
    yaw = float(rng.uniform(-math.pi / 2, math.pi / 2))
    x0 = SHELF["x_front"] + 0.08 * abs(math.cos(yaw)) + 0.033 * abs(math.sin(yaw)) + 0.005
    return {"yaw": round(yaw, 3), "xy": [round(float(x0 + rng.uniform(0.0, 0.04)), 3),
                                         round(float(rng.uniform(-0.15, 0.10)), 3)]}


def relocated_cleanly(scenario: Scenario, plan: RelocationPlan, oid: str, standing: bool = True) -> str:
    """Replay the relocation of `oid` in MuJoCo; assert no contact, the planner's clearances (the fingers FINGER_FLOOR
    over the board it lay on), the bottle standing on its slot (not `standing`: grasped along its axis where the
    hand from above is out of reach, lying on it: test_along_axis_grasp). Returns the summary."""
    checker = MotionChecker(scenario)
    rep = replay_relocation(checker, plan.pick, [plan.carry, plan.retreat], plan.home, oid)
    assert rep.contacts == [], "\n".join(map(str, rep.contacts))
    assert rep.min_arm >= ARM_CLEARANCE, rep.min_arm_at
    assert rep.min_floor >= FINGER_CLEARANCE, rep.min_floor_at  # the fingers over the board it lay on
    assert rep.min_carried >= CARRIED_CLEARANCE, rep.min_carried_at
    assert rep.support_depth <= 0.001
    if not standing:
        p, r = checker.bottle_pose(oid)
        p[2] += scenario.object(oid).radius  # checker.release drops the frame (a lying one's axis) to the board
        o = scenario.object(oid)
        why = lying_on_slot(p, r, scenario, scenario.slot(plan.slot_index), o.radius, o.height)
        assert not why, why
        return rep.summary()
    placed = checker.placed[oid]
    slot = scenario.slot(plan.slot_index)
    assert math.dist(placed[:2], slot) <= PLACE_TOL and placed[2] == pytest.approx(scenario.shelf.bottom_z), \
        (placed, slot)
    assert abs(checker.bottle_pose(oid)[1][2, 2]) >= UPRIGHT, checker.bottle_pose(oid)[1]  # stood up
    return rep.summary()


def test_a_lying_bottle_under_the_shipped_shelf_s_board_is_refused_with_the_headroom_it_needs():
    """lying_start_8's o7 lies on a shelf with 0.26 m of headroom: a hand from above needs 0.45 m there; its axis is
    turned too far from pointing into the shelf for the grasp along it (test_along_axis_grasp)."""
    planner = MotionPlanner(load_scenario("config/scenarios/world/lying_start_8.yaml"), PARAMS)
    a = planner.feasibility("o7", [])
    assert a.label == Label.UNFEASIBLE and a.attempts == 0 and a.blockers == (), a
    assert a.message == (f"{NO_GRASP}o7 lies on the top shelf with 0.26 m of headroom; a grasp from above needs "
                         "0.45 m (the hand straight down, its finger tips 19 mm over the bottle before it comes down "
                         "and 19 mm under the board above); nor along its axis: o7 lies with its axis 1.24 rad "
                         "from pointing into the shelf; a grasp along it approaches within 0.80 rad of straight in"
                         ), a.message
    assert planner.lane_blockers()["o7"] == ()


def test_a_feasible_answer_names_its_action_as_the_task_planner_costs_it():
    """headroom_lying_6: the feasibility answer of the lying o1 says top_grasp (the grasp from above), of a standing
    bottle side_grasp, of an unfeasible question nothing; the task planner's problem costs each obstacle by the same
    action, known from its pose before asking (problem.RelocationProblem.from_scenario; before, answers named no
    action and every relocation cost its weight)."""
    scenario = load_scenario("config/scenarios/headroom_lying_6.yaml")
    planner = MotionPlanner(scenario, PARAMS)
    lying, standing = planner.feasibility("o1", []), planner.feasibility("o2", [])
    assert (lying.label, lying.action) == (Label.OBSTACLE, TOP_GRASP), lying
    assert (standing.label, standing.action) == (Label.OBSTACLE, SIDE_GRASP), standing
    assert planner.certify("o1", []).action == TOP_GRASP
    blocked = planner.feasibility("T", [])
    assert blocked.label == Label.UNFEASIBLE and blocked.action == "", blocked
    factors = ActionCosts(side_grasp=1.0, top_grasp=1.5, push=2.0)
    problem = RelocationProblem.from_scenario(scenario, factors)
    for oid, answer in (("o1", lying), ("o2", standing)):
        assert problem.costs[oid] == pytest.approx(scenario.object(oid).weight * factors.factor(answer.action))
    assert problem.costs["o1"] == pytest.approx(0.45) and problem.weights["o1"] == pytest.approx(0.30)


def test_generated_lying_bottles_are_relocated_standing_touching_nothing_in_mujoco():
    """Every generated lying bottle the planner certifies: no contact, on its slot standing; the others refused
    with a reason. The rate is printed (-s)."""
    planned, refused = [], []
    for seed in SEEDS:
        bottle = drawn_bottle(seed)
        scenario = lying_scene(bottle, seed)
        planner = MotionPlanner(scenario, PARAMS)
        answer = planner.certify("L", [])
        if answer.label != Label.OBSTACLE:
            refused.append((seed, bottle, answer.message))
            continue
        plan = plan_relocation(planner, "L", [])
        pitch = planner.grasp_pitch("L")  # 0: along its axis, placed lying
        planned.append((seed, bottle, pitch, relocated_cleanly(scenario, plan, "L", standing=pitch > 0.0)))
    for seed, bottle, pitch, summary in planned:
        print(f"seed {seed} {bottle} grasped at pitch {pitch:.2f}: {summary}")
    for seed, bottle, why in refused:
        print(f"seed {seed} {bottle}: refused: {why}")
    print(f"lying bottles relocated: {len(planned)} of {len(SEEDS)}")
    assert len([p for p in planned if p[2] > 0.0]) >= 4, refused  # from above
    assert all(why.startswith(NO_GRASP) for *_, why in refused), refused


def test_the_target_behind_a_lying_bottle_is_retrieved_after_it():
    """headroom_lying_6: o1 lies across the front of T and blocks every lane of T's side grasp; taken from above,
    it stands in a slot, then T is relocated into the next one; both replayed in MuJoCo touching nothing."""
    scenario = load_scenario("config/scenarios/headroom_lying_6.yaml")
    planner = MotionPlanner(scenario, PARAMS)
    blocked = planner.feasibility("T", [])
    assert blocked.label == Label.UNFEASIBLE and blocked.blockers
    assert all("o1" in b.objects for b in blocked.blockers), blocked.blockers
    assert planner.certify("o1", []).label == Label.OBSTACLE
    assert planner.feasibility("T", ["o1"]).label == Label.TARGET
    checker, rep, done = MotionChecker(scenario), Report(), []
    for oid in ("o1", "T"):
        plan = plan_relocation(planner, oid, done)
        rep.merge(replay_relocation(checker, plan.pick, [plan.carry, plan.retreat], plan.home, oid))
        done.append(oid)
    print(f"headroom_lying_6 o1, T: {rep.summary()}")
    assert rep.contacts == [], "\n".join(map(str, rep.contacts))
    assert rep.min_arm >= ARM_CLEARANCE and rep.min_carried >= CARRIED_CLEARANCE, rep.summary()
    assert rep.min_floor >= FINGER_CLEARANCE, rep.summary()
    assert abs(checker.bottle_pose("o1")[1][2, 2]) >= UPRIGHT


def test_a_lying_target_is_retrieved_from_above():
    """headroom_lying_target_6: T lies across the front row; before, "no grasp" and no sequence retrieved it."""
    scenario = load_scenario("config/scenarios/headroom_lying_target_6.yaml")
    planner = MotionPlanner(scenario, PARAMS)
    assert planner.certify("T", []).label == Label.TARGET
    print(relocated_cleanly(scenario, plan_relocation(planner, "T", []), "T"))


@pytest.mark.parametrize("limit", [2, pytest.param(None, marks=pytest.mark.extended)])
def test_a_lying_bottle_is_carried_to_its_slot_in_mujoco_physics(limit):
    """relocation.relocate on the simulator's core (test_execution.SimArm: every physics step watched) for every
    generated lying bottle the planner certifies: closed on by the fingers (the simulator grasps the bottle whose
    axis runs through the grasp centre along the fingers' spread: sim.bottle_between_fingers), standing on its slot
    within PLACE_TOL, held within MAX_SLIP, nothing else moved, no contact of the arm or the bottle but the intended
    ones."""
    carried = 0
    for seed in SEEDS:
        if limit is not None and carried >= limit:  # the default run: the first `limit`; -m extended: all
            break
        bottle = drawn_bottle(seed)
        scenario = lying_scene(bottle, seed)
        if MotionPlanner(scenario, PARAMS).grasp_pitch("L") == 0.0:
            continue  # grasped along its axis, placed lying (test_along_axis_grasp)
        end = carried_to_slot(scenario, "L", PARAMS, PLACE_TOL)
        if end is None:
            continue
        w, x, y, z = end[0].quat_wxyz
        assert 1 - 2 * (x * x + y * y) >= UPRIGHT, seed  # standing: its axis within 5 deg of the vertical
        print(f"seed {seed} {bottle}: standing")
        carried += 1
    print(f"lying bottles carried in MuJoCo's physics: {carried}")
    assert carried >= (limit or 4)
