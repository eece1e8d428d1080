"""What the side grasp cannot take, and the collision model of what it does not take (stpik_motion_planner.model:
grasp.grasp_refusal, collision.object_obstacle).

A box too wide across every face the hand can approach, a bottle lying from the start, a jar wider than the open hand
and a conservative object are answered UNFEASIBLE with a message starting "no grasp: " and no lane any removal
clears; a box with a face the hand fits has the lane of that face only (its relocation: test_box_grasp.py). Each is in
the collision scene as the primitive it is (checked against python-fcl's own distances to the primitive placed by
the object model). Before, the planner modelled every object as an upright cylinder of its radius (a box had radius
0: a segment) and answered the pick of a box or of a lying bottle as for a standing bottle.
"""
from __future__ import annotations

import math
from dataclasses import replace

import fcl
import numpy as np
import pytest

from relocation_common import robot_description as rd
from relocation_common.feasibility import NO_GRASP, Label
from relocation_common.scenario import load_scenario
from stpik_motion_planner.model.collision import object_obstacle
from stpik_motion_planner.model.grasp import grasp_refusal, grasp_standoff, hand_opening
from stpik_motion_planner.planning.params import PlannerParams
from stpik_motion_planner.planning.planner import MotionPlanner

BOXES = load_scenario("config/scenarios/world/shapes_box_10.yaml")
LYING = load_scenario("config/scenarios/world/lying_start_8.yaml")
CROWD = load_scenario("config/scenarios/world/crowd_20.yaml")


@pytest.fixture(scope="module")
def boxes() -> MotionPlanner:
    return MotionPlanner(BOXES, PlannerParams.load())


def test_the_hand_opening_comes_from_the_finger_capsules():
    """The gap between finger 1 and fingers 2-3 of the description, at the finger roots and at the tips."""
    f1, f2 = (next(c for c in rd.CAPSULES if c.name == n) for n in ("finger_1", "finger_2"))
    root = f1.p0[0] - f1.radius - (f2.p0[0] + f2.radius)
    tip = f1.p1[0] - f1.radius - (f2.p1[0] + f2.radius)
    assert hand_opening(f1.p0[2] - rd.D67) == pytest.approx(root)
    assert hand_opening(f1.p1[2] - rd.D67) == pytest.approx(tip)
    bottle = next(o for o in BOXES.objects if o.id == "T")
    assert 2 * bottle.radius < hand_opening(grasp_standoff(bottle.radius))  # the paper's bottles fit
    assert grasp_refusal(bottle) == ""


def test_a_box_has_the_lanes_of_the_faces_the_hand_fits_and_no_other(boxes):
    """shapes_box_10's boxes: o9 (80 x 60 mm, yaw -1.25) shows only its 80 mm faces within 0.8 rad of straight in:
    no grasp. o7 (60 x 90 mm, yaw 1.43) has one lane, square to its 90 mm side (yaw 1.43 - pi/2), the fingers across
    its 60 mm; it is blocked by o4, o6 and o9. o8 (50 x 50 x 100 mm) has the lane of its face at yaw -1.36 + pi/2,
    but at its mid-height the hand meets the top board: no lane any removal clears, answered without a grasp."""
    a = boxes.feasibility("o9", [])
    assert a.label == Label.UNFEASIBLE and a.message.startswith(
        f"{NO_GRASP}o9 is a box (box 0.08 x 0.06 x 0.18 m): the narrowest face within 0.80 rad of straight in is 80 mm "
        "across, wider than the open hand"), a.message
    assert a.blockers == () and a.attempts == 0
    lanes = boxes.lane_blockers()
    assert lanes["o9"] == () and lanes["o8"] == ()
    o7 = BOXES.object("o7")
    assert boxes.yaw_tiers("o7") == [[pytest.approx(o7.yaw - math.pi / 2)]]
    (lane,) = lanes["o7"]
    assert lane.certain and lane.objects == {"o4", "o6", "o9"} and lane.lane == "yaw -0.14", lane
    a = boxes.feasibility("o7", [])
    assert a.label == Label.UNFEASIBLE and a.blockers == (lane,), a
    assert boxes.feasibility("o8", []).message == "no collision-free pre-grasp and approach for any yaw"
    assert lanes["T"], "the target keeps its lanes"


def test_a_bottle_lying_from_the_start_is_answered_no_grasp():
    """lying_start_8's o7 lies on the board from the start (the file says so; perception never told the planner):
    before, it was modelled standing and answered as a standing bottle. The shelf's 0.26 m of headroom leave no room
    for the grasp from above (test_lying_grasp.py)."""
    planner = MotionPlanner(LYING, PlannerParams.load())
    a = planner.feasibility("o7", [])
    assert a.label == Label.UNFEASIBLE and a.message.startswith(
        f"{NO_GRASP}o7 lies on the top shelf with 0.26 m of headroom; a grasp from above needs 0.45 m"), a.message
    assert planner.lane_blockers()["o7"] == ()
    lying = planner.scene.bottles["o7"]
    o7 = LYING.object("o7")
    assert lying.hi[2] == pytest.approx(LYING.shelf.top_z + 2 * o7.radius)  # as it lies, not o7.height tall


def test_a_jar_wider_than_the_open_hand_and_a_conservative_object_are_no_grasp():
    jar = next(o for o in CROWD.objects if o.shape == "cylinder" and o.radius >= 0.04)
    why = grasp_refusal(jar)
    assert why.startswith(f"{NO_GRASP}{jar.id} is 80 mm wide, wider than the open hand"), why
    cluster = replace(next(o for o in BOXES.objects if o.id == "o7"), conservative=True)
    assert grasp_refusal(cluster).startswith(f"{NO_GRASP}o7 is a conservative obstacle")


@pytest.mark.parametrize("oid", ["o7", "o8", "o9"])
def test_a_box_is_modelled_as_the_oriented_box_it_is(oid):
    """fcl distances from points around the box to the planner's obstacle and to a box placed independently (its
    corners from the object model's footprint and height) agree, and its bounding box is the footprint's."""
    o = BOXES.object(oid)
    obs = object_obstacle(o, BOXES.shelf.top_z)
    corners = np.asarray(o.footprint().corners)
    np.testing.assert_allclose(obs.lo[:2], corners.min(axis=0), atol=1e-9)
    np.testing.assert_allclose(obs.hi[:2], corners.max(axis=0), atol=1e-9)
    assert obs.lo[2] == pytest.approx(BOXES.shelf.top_z) and obs.hi[2] == pytest.approx(o.top_z)
    c, s = math.cos(o.yaw), math.sin(o.yaw)
    ref = fcl.CollisionObject(fcl.Box(*o.size), fcl.Transform(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]),
                                                              np.array([o.x, o.y, BOXES.shelf.top_z + o.size[2] / 2])))
    rng = np.random.default_rng(0)
    for p in rng.uniform(obs.lo - 0.05, obs.hi + 0.05, size=(40, 3)):
        probe = fcl.CollisionObject(fcl.Sphere(0.005), fcl.Transform(np.eye(3), p))
        d = [fcl.distance(probe, x, fcl.DistanceRequest(), fcl.DistanceResult()) for x in (obs.obj, ref)]
        assert d[0] == pytest.approx(d[1], abs=1e-6)
