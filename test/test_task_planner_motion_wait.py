"""A goal of the task planner that finds a relocate goal of the motion planner still running (an earlier task
planner's: it died) waits for it to end before it reads its scene (TaskPlannerNode._motion_ended, on a stand-in
node: no graph)."""
import threading
import time
import types

import pytest

from qtree_task_planner import task_planner_node as tpn
from qtree_task_planner.executive.outage import Cancelled
from qtree_task_planner.ros_clients import MOTION_WAIT, SceneWatch


def stand_in(motions, relocate_timeout=30.0):
    logged = []
    logger = types.SimpleNamespace(warning=logged.append)
    params = {"relocate_timeout": relocate_timeout, "scene_after_wait": 2.0}
    return types.SimpleNamespace(_motions=motions, get_logger=lambda: logger, p=params.__getitem__,
                                 _scenes=SceneWatch(), logged=logged)


def handle():
    fed = []
    return types.SimpleNamespace(is_cancel_requested=False, publish_feedback=lambda fb: fed.append(fb.phase)), fed


def test_a_goal_waits_for_the_relocation_in_flight_then_for_a_scene_after_it(monkeypatch):
    monkeypatch.setattr(tpn.rclpy, "ok", lambda: True)
    node, (h, fed) = stand_in([2]), handle()  # EXECUTING
    ended = {}

    def motion_ends():
        time.sleep(0.5)
        node._motions = [4]  # SUCCEEDED
        ended["at"] = time.monotonic()
        time.sleep(0.3)
        node._scenes.put(object())

    threading.Thread(target=motion_ends, daemon=True).start()
    t0 = time.monotonic()
    tpn.TaskPlannerNode._motion_ended(node, h, types.SimpleNamespace(phase=""))
    assert "at" in ended and time.monotonic() - t0 >= 0.75  # the motion's end, then the scene after it
    assert fed == [MOTION_WAIT] and node.logged and MOTION_WAIT in node.logged[0]
    assert node._scenes.latest is not None and node._scenes.latest[1] > ended["at"]


def test_no_relocation_in_flight_no_wait_and_one_that_never_ends_aborts_the_goal(monkeypatch):
    monkeypatch.setattr(tpn.rclpy, "ok", lambda: True)
    node, (h, fed) = stand_in([4, 5, 6]), handle()  # succeeded, canceled, aborted: none running
    tpn.TaskPlannerNode._motion_ended(node, h, types.SimpleNamespace(phase=""))
    assert fed == [] and node.logged == []
    node, (h, fed) = stand_in([1], relocate_timeout=0.3), handle()  # ACCEPTED, forever
    with pytest.raises(Cancelled, match="did not end within relocate_timeout 0.3 s"):
        tpn.TaskPlannerNode._motion_ended(node, h, types.SimpleNamespace(phase=""))
