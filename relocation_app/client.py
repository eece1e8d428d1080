"""A client of the relocation graph in the style of nav2_simple_commander's BasicNavigator.

    client = RelocationClient()                       # its own node, spun in a background thread
    client.wait_until_ready()                         # feasibility service, train and relocate actions
    answer = client.plan_feasibility("o2", removed=[])
    client.train(policy="h-eg", search="depth", execute=True, on_feedback=print)
    while not client.is_done():
        time.sleep(0.1)
    result = client.result()                          # TrainPlanner.Result
    client.relocate("o3", removed=["o2"])             # one relocation, same pattern
    oracle = client.feasibility_oracle(replicas=2)    # feasibility for your own search, 2 planners in flight
    client.cancel()                                   # the goal in flight
    client.close()

Every wait has a timeout and a `check` hook (the demo passes the graph's liveness check), so nothing blocks
forever on a dead node. The demo and the graph tests use it; example scripts in scripts/.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Callable

import rclpy
from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile

from qtree_task_planner.replicas import ReplicaOracle
from qtree_task_planner.task_planner_node import ServiceOracle, train_goal
from relocation_common.feasibility import Label, replica_services
from relocation_common.node import ActionClient, call

from .graph import wait_for_interfaces

FEASIBILITY = "/motion_planner/plan_feasibility"
TRAIN = "/task_planner/train"
RELOCATE = "/motion_planner/relocate"


class ClientError(RuntimeError):
    """A goal rejected, a server missing, or no answer in time; the message says which."""


class RelocationClient:
    def __init__(self, name: str = "relocation_client", context=None) -> None:
        if context is None and not rclpy.ok():
            rclpy.init()
        self.node = rclpy.create_node(name, context=context)
        # a deep request queue: a burst of questions is never dropped in this process (default depth 10)
        self._feasibility = self.node.create_client(PlanFeasibility, FEASIBILITY, qos_profile=QoSProfile(depth=1000))
        self._train = ActionClient(self.node, TrainPlanner, TRAIN)
        self._relocate = ActionClient(self.node, RelocateObject, RELOCATE)
        self._executor = SingleThreadedExecutor(context=context)
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._executor.spin, name=name, daemon=True)
        self._thread.start()
        self._goal = None  # ClientGoalHandle in flight
        self._result_future = None

    # -- readiness ------------------------------------------------------------------------------------------
    def wait_until_ready(self, timeout: float = 120.0, check: Callable[[], None] = lambda: None) -> None:
        """Block until the feasibility service and both actions are served; ClientError after `timeout` s."""
        wait_for_interfaces(self.node, [(FEASIBILITY, PlanFeasibility)], [self._train, self._relocate], timeout,
                            check=check, error=ClientError)

    # -- the feasibility question (Eq. 11) ------------------------------------------------------------------
    def plan_feasibility(self, object_id: str, removed=(), timeout: float = 5.0) -> tuple[Label, Any]:
        """(label, response) for relocating `object_id` with `removed` gone; ClientError on a refused request."""
        req = PlanFeasibility.Request(object_id=object_id, removed_ids=list(removed), timeout=float(timeout))
        try:
            res = call(self._feasibility, req, timeout + 10.0)
        except TimeoutError as e:
            raise ClientError(str(e)) from None
        if not res.ok:
            raise ClientError(f"feasibility request refused: {res.message}")
        return Label(res.label), res

    def feasibility_oracle(self, replicas: int = 1, timeout: float = 5.0, margin: float = 2.0) -> ReplicaOracle:
        """The task planner's view of feasibility, for your own search: a FeasibilityOracle and BatchOracle
        (relocation_common.feasibility) over the motion planner and its replicas (/replica_<k>), label only, one
        question in flight per replica, failover when one dies (qtree_task_planner.replicas)."""
        return ReplicaOracle([ServiceOracle(self.node.create_client(PlanFeasibility, name,
                                                                    qos_profile=QoSProfile(depth=1000)),
                                            timeout, margin, connect_wait=timeout)
                              for name in replica_services(FEASIBILITY, replicas)])

    # -- goals ----------------------------------------------------------------------------------------------
    def train(self, on_feedback: Callable | None = None, timeout: float = 30.0,
              check: Callable[[], None] = lambda: None, **fields) -> None:
        """Send a TrainPlanner goal (fields as train_goal: unset ones are the node's parameters)."""
        self._send(self._train, train_goal(**fields), on_feedback, timeout, check)

    def relocate(self, object_id: str, removed=(), on_feedback: Callable | None = None, timeout: float = 30.0,
                 check: Callable[[], None] = lambda: None) -> None:
        """Send a RelocateObject goal: pick `object_id`, carry it to slot len(removed), come home."""
        goal = RelocateObject.Goal(object_id=object_id, removed_ids=list(removed))
        self._send(self._relocate, goal, on_feedback, timeout, check)

    def _send(self, action: ActionClient, goal, on_feedback, timeout: float, check) -> None:
        if self._goal is not None and not self.is_done():
            raise ClientError("a goal is already in flight: wait for it or cancel it first")
        fb = (lambda msg: on_feedback(msg.feedback)) if on_feedback else None
        handle = self._wait(action.send_goal_async(goal, feedback_callback=fb), timeout, check, "goal response")
        if not handle.accepted:
            raise ClientError(f"{action._action_name}: goal rejected (see the node's log for why)")
        self._goal, self._result_future = handle, handle.get_result_async()

    def is_done(self) -> bool:
        return self._result_future is not None and self._result_future.done()

    def wait(self, timeout: float, check: Callable[[], None] = lambda: None):
        """The result of the goal in flight (the action's Result message); ClientError after `timeout` s."""
        if self._result_future is None:
            raise ClientError("no goal was sent")
        return self._wait(self._result_future, timeout, check, "result").result

    def result(self):
        return self._result_future.result().result if self.is_done() else None

    def cancel(self, timeout: float = 10.0) -> None:
        if self._goal is not None and not self.is_done():
            self._wait(self._goal.cancel_goal_async(), timeout, lambda: None, "cancel response")

    @staticmethod
    def _wait(future, timeout: float, check: Callable[[], None], what: str):
        deadline = time.monotonic() + timeout
        while not future.done():
            check()
            if not rclpy.ok():
                raise ClientError(f"shutting down while waiting for the {what}")
            if time.monotonic() > deadline:
                raise ClientError(f"no {what} within {timeout:.0f} s")
            time.sleep(0.05)
        return future.result()

    def close(self) -> None:
        self._executor.shutdown(timeout_sec=1.0)
        self._thread.join(timeout=5.0)
        self.node.destroy_node()
