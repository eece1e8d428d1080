"""stpik_motion_planner.model.scene_update: which perceived bottles replace the planner's (ROS-free); a lying bottle in
the planner's scene and service (collision.lying_cylinder), a dropped one gone from it."""
import math
from dataclasses import replace

import numpy as np
import pytest

from relocation_common.feasibility import Label
from relocation_common.geometry import wxyz_matrix
from relocation_common.scenario import load_scenario
from relocation_common.shelf_object import at_pose
from stpik_motion_planner.model.scene_update import MOVED, merge_perceived
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.service import MotionPlannerService

SC = load_scenario("scenario1_5")
TOP = SC.shelf.top_z
CURRENT = {b.id: b for b in SC.objects}


def perceived(b, base_z, quat=(1.0, 0.0, 0.0, 0.0)):
    """`b` as a scene message brings it (ros_conversions.msg_to_objects) with its base centre at (b.x, b.y, base_z)
    and orientation `quat` (w, x, y, z)."""
    rot = wxyz_matrix(quat)
    return at_pose(b, np.array([b.x, b.y, base_z]) + rot[:, 2] * b.height / 2, rot)


def test_a_bottle_moved_on_the_top_shelf_replaces_the_planners():
    o1 = replace(CURRENT["o1"], x=CURRENT["o1"].x + 0.02)
    merged, _, _, changed, seen = merge_perceived(SC.shelf, CURRENT, [o1, CURRENT["o2"]])
    assert changed == ["o1"] and merged["o1"].x == o1.x and seen == {"o1", "o2"}
    assert merged["o3"] is CURRENT["o3"]  # not seen: keeps its last pose


def test_jitter_below_the_threshold_changes_nothing():
    o1 = replace(CURRENT["o1"], x=CURRENT["o1"].x + MOVED / 2)
    assert merge_perceived(SC.shelf, CURRENT, [o1]).changed == []


def test_lifted_held_or_off_shelf_bottles_are_ignored():
    lifted = replace(CURRENT["o1"], x=CURRENT["o1"].x + 0.05)
    held = replace(CURRENT["o2"], x=CURRENT["o2"].x + 0.05)
    bottom = replace(CURRENT["o3"], x=CURRENT["o3"].x + 0.05)
    merged, lying, gone, changed, seen = merge_perceived(SC.shelf, CURRENT, [perceived(lifted, TOP + 0.03), held,
                                                                            perceived(bottom, SC.shelf.bottom_z)],
                                                     held="o2")
    assert changed == [] and seen == set() and merged == CURRENT and lying == {} and gone == frozenset()


S = math.sqrt(0.5)
ALONG_Y = (S, -S, 0.0, 0.0)  # 90 deg about -x: the bottle's axis along +y, lying


def test_a_tipped_bottle_lies_a_dropped_one_is_gone_and_both_come_back_standing():
    o3 = CURRENT["o3"]
    m = merge_perceived(SC.shelf, CURRENT, [perceived(o3, TOP + o3.radius, ALONG_Y)])
    assert m.changed == ["o3"] and set(m.lying) == {"o3"} and m.seen == {"o3"}
    assert m.lying["o3"].base == pytest.approx((o3.x, o3.y, TOP + o3.radius), abs=1e-9)  # through the centre
    again = merge_perceived(SC.shelf, m.bottles, [perceived(o3, TOP + o3.radius, ALONG_Y)], lying=m.lying)
    assert again.changed == [] and again.lying == m.lying  # the same lying pose: nothing new
    floor = merge_perceived(SC.shelf, m.bottles, [perceived(replace(o3, x=0.3), SC.shelf.bottom_z - 0.3, ALONG_Y)],
                            lying=m.lying)
    assert floor.changed == ["o3"] and floor.gone == {"o3"} and floor.lying == {}
    back = merge_perceived(SC.shelf, floor.bottles, [o3], gone=floor.gone)
    assert back.changed == ["o3"] and back.gone == frozenset() and back.lying == {}


def test_a_bottle_lying_across_a_lane_blocks_it_and_its_phantom_is_gone():
    """o3 of scenario1_5 perceived lying on the top board across o4's lanes (its axis along y, at x 0.66, in front
    of o4). Before, the planner dropped it (not standing on the top shelf) and kept o3 standing where it was: o4
    was FEASIBLE through the lying bottle, and o3 a phantom obstacle at (0.786, -0.206), pickable."""
    service = MotionPlannerService(SC, PlannerParams.load())
    assert service.feasibility("o4", [])[1].label == Label.OBSTACLE  # the lane is clear while o3 stands
    o3 = replace(CURRENT["o3"], x=0.66, y=-0.16)
    assert service.update_scene([b for b in SC.objects if b.id != "o3"] +
                                [perceived(o3, TOP + o3.radius, ALONG_Y)]) == ["o3"]
    answer = service.feasibility("o4", [])[1]
    assert answer.label == Label.UNFEASIBLE and answer.blockers, answer
    assert all("o3" in b.objects for b in answer.blockers), answer.blockers
    lying = service.feasibility("o3", [])[1]
    assert lying.label == Label.UNFEASIBLE and lying.message == ("no grasp: o3 is lying on its side: the side grasp "
                                                                 "takes standing objects only")
    lanes, _ = service.feasibility("", [], all_lanes=True)
    assert lanes["o3"] == ()  # never graspable: no lane any removal clears
    box = service.planner.scene.bottles["o3"]  # the lying cylinder, nothing standing at o3's old place
    np.testing.assert_allclose(box.lo, (0.66 - o3.radius, -0.16 - o3.radius, TOP), atol=1e-6)
    np.testing.assert_allclose(box.hi, (0.66 + o3.radius, -0.16 + o3.height + o3.radius, TOP + 2 * o3.radius),
                               atol=1e-6)
    floor = replace(o3, x=0.3, y=0.0)  # then it rolls off the shelf: no obstacle, nothing to grasp
    assert service.update_scene([perceived(floor, SC.shelf.bottom_z - 0.3 + o3.radius, ALONG_Y)]) == ["o3"]
    assert "o3" not in service.planner.scene.bottles
    assert service.feasibility("o4", [])[1].label == Label.OBSTACLE
    assert service.feasibility("o3", [])[1].message == "o3 left the shelf: nothing to grasp"
