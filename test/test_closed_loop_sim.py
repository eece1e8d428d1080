"""The closed loop's checks against the real MuJoCo simulator core: the default tolerances hold the settled
physics (no difference where nothing happened) and catch each disturbance of jaco2_sim_driver.disturbance; the
closed loop end to end on MuJoCo's physics, in one process, after a bottle tipped over into the target's lane."""
import dataclasses
import math
from dataclasses import replace
from pathlib import Path

import pytest
import yaml
from test_execution import SimArm

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco)
from jaco2_sim_driver import disturbance as dist
from jaco2_sim_driver.messages import ground_truth
from jaco2_sim_driver.sim import Jaco2Sim
from qtree_task_planner.executive.closed_loop import ClosedLoopExecutor
from qtree_task_planner.executive.replan import GeometryCache, replan
from qtree_task_planner.executive.world import SeenObject, remaining_problem, seen_object, verify_relocation
from relocation_common.feasibility import NO_GRASP
from relocation_common.paths import default_scenario
from relocation_common.scenario import Scenario, load_scenario, parse_scenario
from relocation_common.shelf_object import tilt_of_quaternion, unlisted_density
from stpik_motion_planner.execution.relocation import relocate
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.results import PlanningError
from stpik_motion_planner.service import MotionPlannerService

SCENARIO = load_scenario(default_scenario())
SH = SCENARIO.shelf


def perceive(sim) -> dict[str, SeenObject]:
    """Ground truth as the closed loop's scene (as /sim/objects would give it)."""
    out = {}
    for p in sim.object_poses():
        b = SCENARIO.object(p.id)
        out[p.id] = SeenObject(p.id, *p.position, weight=b.weight, is_target=b.is_target,
                               tilt=tilt_of_quaternion(*p.quat_wxyz), radius=b.radius, height=b.height)
    return out


@pytest.fixture(scope="module")
def sim():
    s = Jaco2Sim(SCENARIO)
    s.step(1000)
    return s


def test_settled_scene_is_the_scenario(sim):
    rp = remaining_problem(SCENARIO, perceive(sim), ())
    assert rp.problem is not None and set(rp.problem.ids) == set(SCENARIO.ids)
    assert rp.moved == {} and rp.gone == frozenset() and rp.tipped == ()
    assert rp.free_slots == tuple(range(len(SCENARIO.slots)))


def test_checks_on_the_simulator_see_what_happened_and_only_that(sim):
    sim.reset()
    sim.step(500)
    before = perceive(sim)
    moved = SCENARIO.obstacle_ids[0]
    x, y = SCENARIO.slots[0]
    dist.move_to(sim, moved, x, y, SH.bottom_z)  # relocated as planned (the arm's part is not under test here)
    sim.step(800)
    after = perceive(sim)
    assert verify_relocation(moved, (x, y, SH.bottom_z), before, after).ok
    rp = remaining_problem(SCENARIO, after, [moved])
    assert rp.gone == {moved} and rp.free_slots == tuple(range(1, len(SCENARIO.slots)))
    # a neighbour nudged by 3 cm, another tipped: exactly these two differences
    others = [o for o in SCENARIO.obstacle_ids if o != moved]
    nudged = next(o for o in others if _room_for_push(sim, o, 0.03))
    assert dist.nudge(sim, nudged, 0.0, 0.03).detail["applied"] == pytest.approx([0.0, 0.03], abs=1e-4)
    tipped = next(o for o in others if o != nudged and _tips(sim, o))
    sim.step(1500)
    check = verify_relocation(moved, (x, y, SH.bottom_z), after, perceive(sim))
    assert {(d.kind, d.object_id) for d in check.differences} == {("moved", nudged), ("tipped", tipped)}, \
        check.differences
    rp = remaining_problem(SCENARIO, perceive(sim), [moved])
    assert set(rp.moved) == {nudged, tipped} and rp.tipped == (tipped,) and tipped in rp.problem.obstacles


def _room_for_push(sim, oid, dy) -> bool:
    now = dist.current(sim, oid)
    return dist._room(sim, replace(now, y=now.y + dy)) is None


def _tips(sim, oid) -> bool:
    try:
        dist.tip(sim, oid)
        return True
    except dist.DisturbanceError:
        return False


# ------------------------------------------------------------------------------------------------ a bottle tipped over
# The closed loop on MuJoCo's physics in one process (no ROS graph): the motion planner's service takes the
# simulator's ground truth as /sim/objects carries it (service.update_scene) before every perception of the loop, its
# planner relocates on the simulator's core (test_execution.SimArm: every physics step watched), the re-planner asks
# its answers. headroom_lying_6 with o1 standing in front of T (T's every lane needs o1 gone: o1, T); after o1's
# relocation a bottle of the front row is tipped over towards T's lane (disturbance.tip) and lies across its front:
# each of the two beside o1's place (all there are, none dropped).
PARAMS = dataclasses.replace(PlannerParams.load(), timeout=300.0, carry_timeout=300.0)  # the work budgets decide
TIPS = (("o2", math.pi / 2), ("o3", -math.pi / 2))  # (bottle, direction of its tip)


def tipped_scene(ceiling_z: float) -> Scenario:
    """headroom_lying_6 with o1 standing at (0.69, 0.0), under a board `ceiling_z` high (0.50: 0.48 m of headroom;
    0.28: the shipped shelves' 0.26 m)."""
    data = yaml.safe_load(Path("config/scenarios/headroom_lying_6.yaml").read_text())
    data["shelf"]["ceiling_z"] = ceiling_z
    data["objects"][0] = {"id": "o1", "weight": 0.30, "xy": [0.69, 0.0]}
    data["name"] = f"headroom_tipped_{ceiling_z:.2f}"
    return parse_scenario(data)


class InProcessLoop:
    """Motion planner (MotionPlannerService), simulator and closed loop in one process (the comment above)."""

    def __init__(self, scenario: Scenario, tip: tuple[str, float]) -> None:
        self.tip = tip
        self.sim = Jaco2Sim(scenario)
        self.sim.step(500)
        self.arm = SimArm(self.sim)
        self.service = MotionPlannerService(scenario, PARAMS)
        self.relocations: list[str] = []

    def perceive(self) -> dict[str, SeenObject]:
        truth = [ground_truth(self.sim.scenario, p, unlisted_density()) for p in self.sim.object_poses()]
        self.service.update_scene(truth)  # as the motion planner node takes /sim/objects
        return {o.id: seen_object(o) for o in truth}

    def relocate(self, obj: str, removed: list[str]) -> tuple[bool, str]:
        self.relocations.append(obj)
        try:
            relocate(self.service.planner, self.arm, obj, removed)
        except PlanningError as e:
            return False, str(e)
        self.arm._step(500)
        if len(self.relocations) == 1:  # a bottle tips over into T's lane
            dist.tip(self.sim, *self.tip)
            self.sim.step(1500)
        return True, "relocated"

    def feasibility(self, obj: str, removed: frozenset[str]):
        return self.service.planner.feasibility(obj, removed)

    def lane_blockers(self, removed: frozenset[str]):
        return self.service.planner.lane_blockers(removed)

    def run(self):
        cache = GeometryCache(self)
        scene = self.perceive()
        first = replan(remaining_problem(self.sim.scenario, scene, ()), (), cache)
        assert not isinstance(first, str) and tuple(first[0]) == ("o1", "T"), first
        loop = ClosedLoopExecutor(self.sim.scenario, self.relocate, self.perceive,
                                  lambda rp, banned: replan(rp, banned, cache))
        return loop.run(first[0], scene)


@pytest.mark.parametrize("tip", TIPS)
def test_a_bottle_tipped_into_the_target_s_lane_is_relocated_from_above_and_t_retrieved(tip):
    """0.48 m of headroom: the re-plan asks the motion planner about the lying bottle like any other; its grasp
    from above relocates it standing to a slot, then T. Before, every re-plan banned the tipped bottle ("the side
    grasp takes standing bottles only") and the run ended with no sequence."""
    loop, oid = InProcessLoop(tipped_scene(0.50), tip), tip[0]
    result = loop.run()
    print(result.message, [r.line() for r in result.replans], loop.arm.slip)
    assert result.success, result.message
    assert loop.relocations == ["o1", oid, "T"], loop.relocations
    assert f"{oid} tipped over" in result.replans[0].reason and result.replans[0].sequence == (oid, "T")
    sh = loop.sim.scenario.shelf
    for p in loop.sim.object_poses():  # no false success: o1, the tipped one and T stand on the bottom shelf
        o = ground_truth(loop.sim.scenario, p, unlisted_density())  # a cylinder: either end down (no cap modelled)
        if p.id in ("o1", oid, "T"):
            assert o.support_z == pytest.approx(sh.bottom_z, abs=0.005) and o.axis_tilt < 0.1, o
        else:
            assert o.support_z == pytest.approx(sh.top_z, abs=0.005) and o.axis_tilt < 0.1, o
    assert loop.arm.unintended == {}, loop.arm.unintended


@pytest.mark.parametrize("tip", TIPS)
def test_under_the_shipped_shelf_s_board_a_lying_bottle_stays_and_the_give_up_names_the_headroom(tip):
    """0.26 m of headroom: the motion planner refuses the lying bottle with the headroom a grasp from above needs.
    o2 lying closes every lane of T: the re-plan's "no sequence" line names the headroom (before: "the side grasp
    takes standing bottles only"). o3 lying leaves T's lanes from the right open: retrieved around it (o2, o4, T),
    o3 left lying where it fell."""
    loop, oid = InProcessLoop(tipped_scene(0.28), tip), tip[0]
    result = loop.run()
    truth = {p.id: ground_truth(loop.sim.scenario, p, unlisted_density()) for p in loop.sim.object_poses()}
    assert truth[oid].lying and truth[oid].support_z == pytest.approx(loop.sim.scenario.shelf.top_z, abs=0.005)
    if oid == "o3":
        assert result.success and loop.relocations == ["o1", "o2", "o4", "T"], (loop.relocations, result.message)
        assert truth["T"].support_z == pytest.approx(loop.sim.scenario.shelf.bottom_z, abs=0.005)
        return
    assert not result.success and loop.relocations == ["o1"], (loop.relocations, result.message)
    assert result.message.startswith("no sequence remains: T cannot be reached") and \
        f"every lane of T holds an object the hand cannot grasp ({oid})" in result.message and \
        f"{NO_GRASP}{oid} lies on the top shelf with 0.26 m of headroom; a grasp from above needs 0.45 m" \
        in result.message, result.message
