"""The push through the motion_planner node as a real process with the MuJoCo driver over DDS, on a generated "X
beside T" layout (test/push_layouts.py, seed 0): PlanFeasibility action "push" answers with the action, the predicted
end pose and the trajectory; asked before the push on the scene with X at that end (moved_ids, moved_to: what would
follow it), T's side grasp is feasible; RelocateObject action "push" carries it out (succeeded only if the
simulator's scene shows X at that pose); afterwards T's side grasp, unfeasible before, is feasible, as the what-if
answer said; a bad action or a bad what-if scene is refused."""

import pytest
import yaml
from push_layouts import beside_data, beside_layout
from ros_procs import REPO, RosGraph, future_result

pytest.importorskip("rclpy")
from qtree_relocation_msgs.action import RelocateObject
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.qos import QoSDurabilityPolicy, QoSProfile

from relocation_common.feasibility import Label
from relocation_common.ros_conversions import moved_to_fields, msg_to_objects

pytestmark = pytest.mark.graph

SRV = "/motion_planner/plan_feasibility"
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
SEED = 0


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("push_node")
    scene = tmp / "beside.yaml"
    scene.write_text(yaml.safe_dump(beside_data(SEED)))
    g = RosGraph(tmp)
    try:
        g.driver = g.start("jaco2_sim_driver.driver_node", params_file=REPO / "config" / "jaco2_sim_driver.yaml",
                           params={"camera_rate": 0.0, "scenario": str(scene)})
        g.planner = g.start("stpik_motion_planner.motion_planner_node",
                            params_file=REPO / "config" / "motion_planner.yaml",
                            params={"scene_topic": "/sim/objects", "scenario": str(scene)})
        g.objects = g.probe.collect("/sim/objects", ObjectArray, LATCHED)
        g.action = g.relocate_client(g.driver, g.planner)
        g.objects.wait(timeout=30)
        yield g
    finally:
        g.close()


def _ask(g, object_id, action="", clear_for="", moved=None):
    ids, points = moved_to_fields(moved or {})
    req = PlanFeasibility.Request(object_id=object_id, timeout=60.0, action=action, clear_for=clear_for,
                                  moved_ids=ids, moved_to=points)
    return g.probe.call(PlanFeasibility, SRV, req, timeout=90)


def _push(g, object_id, clear_for, action="push", timeout=180.0):
    fut = g.action.send_goal_async(RelocateObject.Goal(object_id=object_id, action=action, clear_for=clear_for))
    handle = future_result(fut, 30, "goal response never came")
    assert handle.accepted
    return future_result(handle.get_result_async(), timeout)


def test_a_push_is_answered_carried_out_and_opens_the_targets_lane(graph):
    assert Label(_ask(graph, "T").label) == Label.UNFEASIBLE  # X beside it: no side grasp of T
    res = _ask(graph, "X", "push", "T")
    assert res.ok and Label(res.label) == Label.OBSTACLE and res.action == "push", res.message
    assert len(res.trajectory.points) > 100
    x = beside_layout(SEED).object("X")
    end = res.end_pose.position
    assert end.x > x.x + 0.015 and res.end_pose.orientation.w == 1.0
    what_if = _ask(graph, "T", moved={"X": (end.x, end.y)})  # what would follow the push, asked before it
    assert what_if.ok and Label(what_if.label) == Label.TARGET, what_if.message
    assert Label(_ask(graph, "T").label) == Label.UNFEASIBLE  # the planner's own scene: unchanged
    out = _push(graph, "X", "T")
    assert out.status == 4, out.result.message  # succeeded: the scene shows X within slot_tolerance of end_pose
    graph.objects.clear()
    seen = {o.id: o for o in msg_to_objects(graph.objects.wait(timeout=5)[-1])}
    assert abs(seen["X"].x - end.x) < 0.01 and abs(seen["X"].y - end.y) < 0.01, (seen["X"], end)
    t = _ask(graph, "T")
    assert t.ok and Label(t.label) == Label.TARGET, t.message  # the lane the push opened


def test_a_bad_action_is_refused_and_the_node_keeps_serving(graph):
    res = _ask(graph, "X", "shove", "T")
    assert not res.ok and "action must be" in res.message
    res = _ask(graph, "X", "push", "")
    assert not res.ok and "clear_for" in res.message
    req = PlanFeasibility.Request(object_id="T", moved_ids=["X"])  # no position for X
    res = graph.probe.call(PlanFeasibility, SRV, req, timeout=90)
    assert not res.ok and "must pair up" in res.message, res.message
    t = beside_layout(SEED).object("T")
    res = _ask(graph, "T", moved={"X": (t.x, t.y + 0.01)})
    assert not res.ok and "overlaps T" in res.message, res.message
    out = _push(graph, "X", "T", action="shove", timeout=30)
    assert out.status == 6 and "action must be" in out.result.message  # aborted with the reason
    assert _ask(graph, "X").ok
