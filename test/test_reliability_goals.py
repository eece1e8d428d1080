"""The motion planner never reports a success that is not true, seen from outside through its ROS interfaces (the
MuJoCo driver over DDS): RelocateObject goals checked against the scene, the destination a free slot of the scene,
scene updates checked against the scenario, parameters read-only while it runs (docs/reliability.md).

The planner's scene topic is relayed by this test from the driver's ground truth (/sim/objects), so that a test can
show it a scene that differs from the physics in one known way."""
import copy
import math
import time
from dataclasses import replace

import numpy as np
import pytest
from qtree_relocation_msgs.action import RelocateObject
from qtree_relocation_msgs.msg import ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from ros_procs import REPO, RosGraph, future_result

from relocation_common.paths import default_scenario
from relocation_common.ros_conversions import msg_to_objects, object_to_msg
from relocation_common.scenario import load_scenario

pytestmark = pytest.mark.graph
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
SC = load_scenario(default_scenario())
RELAYED = "/test/objects"


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    g = RosGraph(tmp_path_factory.mktemp("goals"))
    try:
        g.driver = g.start("jaco2_sim_driver.driver_node", params_file=REPO / "config" / "jaco2_sim_driver.yaml",
                           params={"camera_rate": 0.0})
        g.planner = g.start("stpik_motion_planner.motion_planner_node",
                            params_file=REPO / "config" / "motion_planner.yaml",
                            params={"scene_topic": RELAYED, "carry_timeout": 60.0})  # a safety net only: load-proof
        g.pub = g.probe.publisher(ObjectArray, RELAYED, LATCHED)
        g.mutate = lambda msg: msg
        g.truth = g.probe.collect("/sim/objects", ObjectArray, LATCHED)
        g.probe.node.create_subscription(ObjectArray, "/sim/objects", lambda m: g.pub.publish(g.mutate(m)), LATCHED)
        g.action = g.relocate_client(g.driver, g.planner)
        g.truth.wait(timeout=30)
        yield g
    finally:
        g.close()


def _done(fut, timeout):
    return future_result(fut, timeout, "no answer")


def _relocate(g, object_id, removed=(), timeout=120.0):
    """(accepted, result) of a RelocateObject goal."""
    handle = _done(g.action.send_goal_async(RelocateObject.Goal(object_id=object_id, removed_ids=list(removed))), 30)
    if not handle.accepted:
        return False, None
    return True, _done(handle.get_result_async(), timeout)


def _truth(g) -> dict[str, np.ndarray]:
    g.truth.clear()
    msg = g.truth.wait(timeout=5)[-1]
    return {o.id: o.base() for o in msg_to_objects(msg)}  # base centres


def _wait_log(g, words, timeout=10.0):
    deadline = time.monotonic() + timeout
    while words not in g.planner.log():
        assert time.monotonic() < deadline, f"{words!r} not in the planner's log:\n{g.planner.log()[-3000:]}"
        time.sleep(0.05)


def test_a_scene_with_an_unknown_id_or_a_far_pose_is_dropped_whole(graph):
    """Old code: 'scene updated: ['zz3']', the phantom zz3 kept until restart (PlanFeasibility answered for it)
    and every later training ended without a sequence."""
    def renamed(msg):
        msg = copy.deepcopy(msg)
        next(o for o in msg.objects if o.id == "o3").id = "zz3"
        return msg

    def far(msg):
        msg = copy.deepcopy(msg)
        next(o for o in msg.objects if o.id == "o5").pose.position.x = 1e6
        return msg

    for mutate, words in ((renamed, "id 'zz3' is not in scenario"), (far, "more than 0.5 m away from the shelf")):
        graph.mutate = mutate
        _wait_log(graph, words)
        graph.mutate = lambda msg: msg
    res = graph.probe.call(PlanFeasibility, "/motion_planner/plan_feasibility",
                           PlanFeasibility.Request(object_id="zz3", label_only=True), timeout=30)
    assert not res.ok and "unknown object id 'zz3'" in res.message, res.message
    assert "zz3" not in graph.planner.log().split("scene updated")[-1].split("\n")[0]
    assert graph.planner.alive


def test_a_removed_set_that_the_scene_contradicts_is_refused_with_the_reason(graph):
    """Old code: o6 with removed o2, o3 while both stood: 'relocated o6', success; o2 pushed 65-94 mm, o3 tipped."""
    before = _truth(graph)
    accepted, res = _relocate(graph, "o6", ["o2", "o3"])
    assert accepted and res.status == 6, (res.status, res.result.message)  # accepted, then ABORTED with the reason
    msg = res.result.message
    assert not res.result.success and "o2, o3" in msg and "standing on the top shelf" in msg, msg
    after = _truth(graph)
    assert max(float(np.linalg.norm(after[i] - before[i])) for i in SC.ids) < 0.005  # nothing moved


@pytest.mark.slow
def test_the_destination_is_a_free_slot_of_the_scene_and_a_relocated_object_is_refused(graph):
    """The scene shows o2 in slot 0 of the bottom shelf (the relay says so) and o3 is sent with removed=[]: the old
    node took slot len(removed) = 0, where o2 stands, and shoved it; now o3 goes to slot 1, the first free one."""
    slot0 = SC.slots[0]
    relayed = []

    def o2_in_slot0(msg):
        msg = copy.deepcopy(msg)
        k = next(k for k, o in enumerate(msg.objects) if o.id == "o2")
        o2 = msg_to_objects(msg)[k]
        msg.objects[k] = object_to_msg(replace(o2, x=slot0[0], y=slot0[1], support_z=SC.shelf.bottom_z))
        relayed.append(time.monotonic())
        return msg

    graph.mutate = o2_in_slot0
    deadline = time.monotonic() + 20.0  # the planner must have the changed scene before the goal (a loaded machine)
    while len(relayed) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(relayed) >= 3, "the driver's ground truth stopped coming"
    time.sleep(0.3)
    before = _truth(graph)
    accepted, res = _relocate(graph, "o3", [])
    assert accepted and res.result.success, res.result.message
    assert res.result.message == "relocated o3 to slot 1", res.result.message
    time.sleep(0.3)
    after = _truth(graph)
    np.testing.assert_allclose(after["o3"], (*SC.slots[1], SC.shelf.bottom_z), atol=0.01)
    moved = {i: float(np.linalg.norm(after[i] - before[i])) for i in SC.ids if i != "o3"}
    assert max(moved.values()) < 0.01, moved
    accepted, res = _relocate(graph, "o3", ["o2"])  # on the bottom shelf now: nothing to pick up
    assert accepted and res.status == 6 and "already relocated" in res.result.message, res.result.message


def test_parameters_are_read_only_while_the_node_runs(graph):
    """Old code: `ros2 param set /motion_planner state_timeout nan` was taken, bypassing the start-up checks."""
    req = SetParameters.Request(parameters=[Parameter(name="state_timeout", value=ParameterValue(
        type=ParameterType.PARAMETER_DOUBLE, double_value=math.nan))])
    res = graph.probe.call(SetParameters, "/motion_planner/set_parameters", req, timeout=10)
    assert not res.results[0].successful and "read-only" in res.results[0].reason, res.results[0]
