"""Closed-loop retrieval over DDS (docs/closed_loop.md): the sim driver, the motion planner and the task planner as
processes on the ground-truth scene (/sim/objects), with one disturbance from the driver's `disturbance_plan`.

scenario1_5: after the first relocation of the optimum (o4 T) the driver nudges o3 13 cm sideways into o4's old
place, in front of the target again. The plan's moment "after relocation 1" comes when the arm is back home,
just before the motion planner checks the outcome: its check sees o3 moved and reports o4's relocation as failed.
The closed loop counts o4 as relocated (seen on the bottom shelf), re-plans (o3 T) and retrieves the target; the
open-loop baseline ends the goal at that failure. Measured: closed 69 s (3 relocations), open 22 s. Every run, closed
or open, successful or not, ends with the arm home and nothing in the gripper (relocation_app.final_state)."""
import json
import math
import time

import pytest
from qtree_relocation_msgs.action import TrainPlanner
from qtree_relocation_msgs.msg import ObjectArray
from rclpy.qos import QoSDurabilityPolicy, QoSProfile
from ros_procs import REPO, RosGraph, planner_has_scene
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from jaco2_sim_driver.disturbance import Disturbance, DisturbancePlan
from qtree_task_planner.ros_clients import train_goal
from relocation_app.final_state import final_state
from relocation_common.node import ActionClient
from relocation_common.ros_conversions import msg_to_objects
from relocation_common.scenario import load_scenario

pytestmark = pytest.mark.graph
LATCHED = QoSProfile(depth=1, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
RECORDS = QoSProfile(depth=100, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
SCENE = REPO / "config" / "scenarios" / "scenario1_5.yaml"
SC = load_scenario(SCENE)
# the ids standing on the top shelf after o4 left, sorted: T o1 o2 o3 o5: choice 0.7 picks o3
NUDGE = DisturbancePlan(0, (Disturbance("nudge", "after", 0, choice=0.7, amount=0.13, direction=math.pi / 2),))


def _run(tmp_path, closed_loop: bool):
    """(TrainPlanner result, ~/execution dict, disturbance records, final ground truth, wall s, the task planner's log,
    final_state: arm home, gripper empty)."""
    with RosGraph(tmp_path) as g:
        g.start("jaco2_sim_driver.driver_node", params_file=REPO / "config" / "jaco2_sim_driver.yaml",
                params={"camera_rate": 0.0, "disturbance_plan": f"'{NUDGE.to_json()}'",
                                                               "scenario": str(SCENE)})  # YAML-quoted
        g.start("stpik_motion_planner.motion_planner_node", params_file=REPO / "config" / "motion_planner.yaml",
                params={"scene_topic": "/sim/objects", "scenario": str(SCENE)})
        tp = g.start("qtree_task_planner.task_planner_node", params_file=REPO / "config" / "task_planner.yaml",
                     params={"scene_topic": "/sim/objects", "closed_loop": closed_loop, "scenario": str(SCENE)})
        execution = g.probe.collect("/task_planner/execution", String, LATCHED)
        records = g.probe.collect("/sim/disturbances", String, RECORDS)
        truth = g.probe.collect("/sim/objects", ObjectArray, LATCHED)
        joints = g.probe.collect("/j2s7s300_driver/out/joint_state", JointState, 10)
        client = ActionClient(g.probe.node, TrainPlanner, "/task_planner/train")
        deadline = time.monotonic() + 60
        while not client.wait_for_server(timeout_sec=0.5):
            assert tp.alive() and time.monotonic() < deadline, tp.log()[-3000:]
        truth.wait(timeout=30)
        planner_has_scene(g.probe)  # the test's scene is not the planner's: its goal would wait only scene_wait
        t0 = time.monotonic()
        handle = _wait(client.send_goal_async(train_goal(seed=1, max_episodes=5, execute=True, execute_optimum=True)),
                       60)  # the goal response: 30 s was once too short under load
        result = _wait(handle.get_result_async(), 400).result
        wall = time.monotonic() - t0
        out = json.loads(execution.wait(timeout=10)[-1].data)
        truth.clear()
        joints.clear()
        last = truth.wait(timeout=10)[-1]
        end = final_state(joints.wait(timeout=10)[-1], last)
        final = {o.id: o for o in msg_to_objects(last, require_target=False)}
        return result, out, [json.loads(m.data) for m in records.wait(timeout=10)], final, wall, tp.log(), end


def _wait(fut, timeout):
    deadline = time.monotonic() + timeout
    while not fut.done():
        assert time.monotonic() < deadline, "no answer"
        time.sleep(0.05)
    return fut.result()


@pytest.mark.slow
def test_a_nudge_after_the_first_relocation_is_seen_and_re_planned_around(tmp_path):
    result, out, records, final, wall, log, end = _run(tmp_path, closed_loop=True)
    print(f"closed loop: {wall:.0f} s; {result.message}; re-plans {[r['reason'] for r in out['replans']]}")
    assert [r["kind"] for r in records] == ["nudge"] and records[0]["object"] == "o3", records
    assert list(result.optimal_sequence) == ["o4", SC.target_id], result.optimal_sequence
    assert result.success and out["success"], (result.message, out, log[-3000:])
    assert out["replans"] and "o3 moved" in out["replans"][0]["reason"], out["replans"]
    assert abs(final[SC.target_id].support_z - SC.shelf.bottom_z) < 0.02, final[SC.target_id]
    assert end["arm_home"] and end["gripper_empty"], end


@pytest.mark.extended  # 30 s: the open-loop executor's failure is also checked without processes (test_closed_loop)
def test_the_open_loop_baseline_fails_on_the_same_disturbance(tmp_path):
    result, out, records, final, wall, log, end = _run(tmp_path, closed_loop=False)
    print(f"open loop: {wall:.0f} s; {result.message}")
    assert [r["kind"] for r in records] == ["nudge"], records
    assert not result.success and not out["replans"], (result.message, out)
    assert abs(final[SC.target_id].support_z - SC.shelf.top_z) < 0.02  # the target never left the top shelf
    assert end["arm_home"] and end["gripper_empty"], end  # the failed relocation ended as planned: home, hand empty
