"""stpik_motion_planner.model.scene_update: which perceived bottles replace the planner's (ROS-free); a bottle tipped
over in the planner's scene and service: lying flat (a lying ShelfObject, taken from above where the headroom allows,
modelled as MuJoCo has it), leaning (collision.lying_cylinder, an obstacle only); a dropped one gone from it."""
import math
from dataclasses import replace

import numpy as np
import pytest

import jaco2_sim_driver  # noqa: F401  (MUJOCO_GL=egl before mujoco)
from jaco2_sim_driver import disturbance as dist
from jaco2_sim_driver.messages import ground_truth
from jaco2_sim_driver.sim import Jaco2Sim
from relocation_common.feasibility import NO_GRASP, Label
from relocation_common.geometry import rotvec_matrix, wxyz_matrix
from relocation_common.scenario import load_scenario
from relocation_common.shelf_object import at_pose, unlisted_density
from stpik_motion_planner.model.scene_update import MOVED, merge_perceived
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.service import MotionPlannerService

SC = load_scenario("scenario1_5")
TOP = SC.shelf.top_z
CURRENT = {b.id: b for b in SC.objects}
FLAT = PlannerParams.load().flat_tilt


def perceived(b, base_z, quat=(1.0, 0.0, 0.0, 0.0)):
    """`b` as a scene message brings it (ros_conversions.msg_to_objects) with its base centre at (b.x, b.y, base_z)
    and orientation `quat` (w, x, y, z)."""
    rot = wxyz_matrix(quat)
    return at_pose(b, np.array([b.x, b.y, base_z]) + rot[:, 2] * b.height / 2, rot)


def test_a_bottle_moved_on_the_top_shelf_replaces_the_planners():
    o1 = replace(CURRENT["o1"], x=CURRENT["o1"].x + 0.02)
    merged, _, _, changed, seen, _ = merge_perceived(SC.shelf, CURRENT, [o1, CURRENT["o2"]], FLAT)
    assert changed == ["o1"] and merged["o1"].x == o1.x and seen == {"o1", "o2"}
    assert merged["o3"] is CURRENT["o3"]  # not seen: keeps its last pose


def test_jitter_below_the_threshold_changes_nothing():
    o1 = replace(CURRENT["o1"], x=CURRENT["o1"].x + MOVED / 2)
    assert merge_perceived(SC.shelf, CURRENT, [o1], FLAT).changed == []


def test_lifted_held_or_off_shelf_bottles_are_ignored():
    lifted = replace(CURRENT["o1"], x=CURRENT["o1"].x + 0.05)
    held = replace(CURRENT["o2"], x=CURRENT["o2"].x + 0.05)
    bottom = replace(CURRENT["o3"], x=CURRENT["o3"].x + 0.05)
    merged, lying, gone, changed, seen, _ = merge_perceived(SC.shelf, CURRENT, [perceived(lifted, TOP + 0.03), held,
                                                                               perceived(bottom, SC.shelf.bottom_z)],
                                                            FLAT, held="o2")
    assert changed == [] and seen == set() and merged == CURRENT and lying == {} and gone == frozenset()


S = math.sqrt(0.5)
ALONG_Y = (S, -S, 0.0, 0.0)  # 90 deg about -x: the bottle's axis along +y, lying


def measured(b, above_flat):
    """`b` tipped over towards +y as a measured pose has it: its axis `above_flat` rad above horizontal (a bottle on
    the board is never exactly flat in a measurement), its lowest point on the top board, its lower end at b.x, b.y."""
    rot = rotvec_matrix([-(math.pi / 2 - above_flat), 0.0, 0.0])
    c = rot[:, 2] * b.height / 2
    return at_pose(b, (b.x + c[0], b.y + c[1], TOP + c[2] + b.radius * math.cos(above_flat)), rot)


def test_a_tipped_bottle_lies_flat_a_dropped_one_is_gone_and_both_come_back_standing():
    """A bottle measured 0.02 rad from flat is the lying ShelfObject a scenario gives (before: a raw pose, "lying on
    its side", never graspable), about the measured centre; measured again 0.03 rad from flat: nothing new."""
    o3 = CURRENT["o3"]
    seen = measured(o3, 0.02)
    assert seen.lying and seen.tilt == pytest.approx(math.pi / 2 - 0.02)  # as measured: not exactly flat
    m = merge_perceived(SC.shelf, CURRENT, [seen], FLAT)
    assert m.changed == ["o3"] and m.lying == {} and m.seen == {"o3"}
    flat = m.bottles["o3"]
    assert flat.lying and flat.tilt is None and math.cos(flat.yaw) == pytest.approx(0.0, abs=1e-9)  # along y
    np.testing.assert_allclose(flat.centre(), seen.centre(), atol=1e-9)
    assert flat.support_z == pytest.approx(TOP, abs=0.002)  # its ends moved by 80 mm x sin(0.02) at most
    again = merge_perceived(SC.shelf, m.bottles, [measured(o3, 0.03)], FLAT, lying=m.lying)
    assert again.changed == [] and again.lying == {}  # lying flat where it lay: nothing new
    floor = merge_perceived(SC.shelf, m.bottles, [perceived(replace(o3, x=0.3), SC.shelf.bottom_z - 0.3, ALONG_Y)],
                            FLAT, lying=m.lying)
    assert floor.changed == ["o3"] and floor.gone == {"o3"} and floor.lying == {}
    back = merge_perceived(SC.shelf, floor.bottles, [o3], FLAT, gone=floor.gone)
    assert back.changed == ["o3"] and back.gone == frozenset() and back.lying == {} and not back.bottles["o3"].lying


def test_a_leaning_bottle_is_an_obstacle_only():
    """A bottle 0.5 rad from flat (leaning on something) keeps its measured pose: the leaning cylinder, no grasp."""
    service = MotionPlannerService(SC, PlannerParams.load())
    leaning = measured(CURRENT["o3"], 0.5)
    assert service.update_scene([b for b in SC.objects if b.id != "o3"] + [leaning]) == ["o3"]
    assert set(service.planner.lying) == {"o3"}
    assert service.planner.scenario.object("o3").tilt == pytest.approx(math.pi / 2 - 0.5)
    answer = service.feasibility("o3", [])[1]
    assert answer.label == Label.UNFEASIBLE and answer.message.startswith(f"{NO_GRASP}o3 leans"), answer.message


def test_a_bottle_lying_across_a_lane_blocks_it_and_its_phantom_is_gone():
    """o3 of scenario1_5 perceived lying on the top board across o4's lanes (its axis along y, at x 0.66, in front
    of o4). Before, the planner dropped it (not standing on the top shelf) and kept o3 standing where it was: o4
    was FEASIBLE through the lying bottle, and o3 a phantom obstacle at (0.786, -0.206), pickable. Lying flat on
    the shipped shelf, the grasp from above is refused with the headroom (0.26 m) it would need."""
    service = MotionPlannerService(SC, PlannerParams.load())
    assert service.feasibility("o4", [])[1].label == Label.OBSTACLE  # the lane is clear while o3 stands
    o3 = replace(CURRENT["o3"], x=0.66, y=-0.16)
    assert service.update_scene([b for b in SC.objects if b.id != "o3"] +
                                [perceived(o3, TOP + o3.radius, ALONG_Y)]) == ["o3"]
    answer = service.feasibility("o4", [])[1]
    assert answer.label == Label.UNFEASIBLE and answer.blockers, answer
    assert all("o3" in b.objects for b in answer.blockers), answer.blockers
    lying = service.feasibility("o3", [])[1]
    assert lying.label == Label.UNFEASIBLE and lying.message == (  # across the shelf under a low board
        "no grasp: o3 lies on the top shelf with 0.26 m of headroom; a grasp from above needs 0.45 m (the hand "
        "straight down, its finger tips 19 mm over the bottle before it comes down and 19 mm under the board above); "
        "nor along its axis: o3 lies with its axis 1.57 rad from pointing into the shelf; a grasp along it approaches "
        "within 0.80 rad of straight in")
    lanes, _ = service.feasibility("", [], all_lanes=True)
    assert lanes["o3"] == ()  # never graspable here: no lane any removal clears
    box = service.planner.scene.bottles["o3"]  # the lying cylinder, nothing standing at o3's old place
    np.testing.assert_allclose(box.lo, (0.66 - o3.radius, -0.16, TOP), atol=1e-6)
    np.testing.assert_allclose(box.hi, (0.66 + o3.radius, -0.16 + o3.height, TOP + 2 * o3.radius), atol=1e-6)
    floor = replace(o3, x=0.3, y=0.0)  # then it rolls off the shelf: no obstacle, nothing to grasp
    assert service.update_scene([perceived(floor, SC.shelf.bottom_z - 0.3 + o3.radius, ALONG_Y)]) == ["o3"]
    assert "o3" not in service.planner.scene.bottles
    assert service.feasibility("o4", [])[1].label == Label.OBSTACLE
    assert service.feasibility("o3", [])[1].message == "o3 left the shelf: nothing to grasp"


MODEL_TOL = 0.003  # m: the ends of a lying bottle's axis in the planner's model from MuJoCo's


def test_bottles_lying_in_mujoco_lie_flat_in_the_planner_as_there_and_are_taken_from_above():
    """headroom_lying_6 in MuJoCo's physics, o2 tipped over (disturbance.tip) and settled: the ground truth as
    /sim/objects publishes it (measured poses, never exactly flat) makes o1 and o2 lying ShelfObjects whose
    cylinders in the planner's collision scene are MuJoCo's within MODEL_TOL at both ends; o1 is taken from above
    (before: "is lying on its side", never graspable)."""
    sc = load_scenario("config/scenarios/headroom_lying_6.yaml")
    sim = Jaco2Sim(sc)
    sim.step(500)
    dist.tip(sim, "o2")
    sim.step(1500)
    truth = [ground_truth(sc, p, unlisted_density()) for p in sim.object_poses()]
    service = MotionPlannerService(sc, PlannerParams.load())
    assert "o2" in service.update_scene(truth)
    for oid in ("o1", "o2"):
        o = service.planner.scenario.object(oid)
        assert o.lying and o.tilt is None, o
        ob = service.planner.scene.bottles[oid].obj
        c, axis = np.asarray(ob.getTranslation()), np.asarray(ob.getRotation())[:, 2] * o.height / 2
        g = sim.model.geom(f"{oid}_geom").id
        mc, maxis = sim.data.geom_xpos[g], sim.data.geom_xmat[g].reshape(3, 3)[:, 2] * sim.model.geom_size[g][1]
        assert sim.model.geom_size[g][:2] == pytest.approx((o.radius, o.height / 2))
        ends = max(min(np.linalg.norm(c + s * axis - mc - maxis), np.linalg.norm(c + s * axis - mc + maxis))
                   for s in (1, -1))
        print(f"{oid}: the planner's axis ends {ends * 1000:.2f} mm from MuJoCo's (measured tilt "
              f"{next(t for t in truth if t.id == oid).axis_tilt:.4f} rad)")
        assert ends <= MODEL_TOL, (oid, ends)
    assert service.planner.not_graspable("o1") == "" and service.planner.grasp_pitch("o1") > 0


def test_an_unlisted_object_left_out_is_counted_only_in_view_and_with_no_relocation_running():
    """scene_update's phantom rule (merge_perceived's `missing`, `phantom_scenes`): u1 stands in front of the shelf
    with nothing before it, u2 behind o4. A scene without either counts for u1 only (u2 may be hidden); during a
    relocation (`held`) it counts for none; the count reaching phantom_scenes drops u1. Before, both stayed."""
    u1 = replace(CURRENT["o1"], id="u1", listed=False, x=0.68, y=-0.10)
    u2 = replace(CURRENT["o1"], id="u2", listed=False, x=0.90, y=-0.08)
    current = {**CURRENT, "u1": u1, "u2": u2}
    scene = list(CURRENT.values())
    m = merge_perceived(SC.shelf, current, scene, FLAT, missing={}, phantom_scenes=2)
    assert m.missing == {"u1": 1} and m.changed == [] and {"u1", "u2"} <= set(m.bottles)
    during = merge_perceived(SC.shelf, m.bottles, scene, FLAT, held="o1", missing=m.missing, phantom_scenes=2)
    assert during.missing == {"u1": 1} and during.changed == []
    m = merge_perceived(SC.shelf, m.bottles, scene, FLAT, missing=m.missing, phantom_scenes=2)
    assert m.changed == ["u1"] and "u1" not in m.bottles and "u2" in m.bottles and m.missing == {}
