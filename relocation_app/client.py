"""A client of the relocation graph in the style of nav2_simple_commander's BasicNavigator.

    with RelocationClient() as client:                # its own node and rclpy Context, spun in a background thread
        client.wait_until_ready()                     # feasibility service, train and relocate actions
        label, answer = client.plan_feasibility("o2", removed=[])
        client.train(policy="h-eg", search="depth", execute=True, on_feedback=print)
        while not client.is_done():
            time.sleep(0.1)                           # client.feedback(): the latest feedback message
        result = client.result()                      # GoalResult: status (TaskResult), message, the action's Result
        client.relocate("o3", removed=["o2"])         # one relocation, same pattern; client.wait(timeout) blocks
        oracle = client.feasibility_oracle(replicas=2)  # feasibility for your own search, 2 planners in flight
        client.cancel()                               # the goal in flight

Context: without `context=`, the client initialises a Context of its own (no signal handlers: Ctrl-C stays a
KeyboardInterrupt in your thread) and shuts it down on close; rclpy's global context, which your program may own,
is never touched. With `context=` (initialised by you), the client uses it and leaves it running. close(), or the
end of the with-block, cancels a goal still in flight, stops the spin thread and destroys the node.

Every wait has a timeout and a `check` hook (the demo passes the graph's liveness check), so nothing blocks
forever on a dead node. The demo and the graph tests use it; example scripts in scripts/.
"""
from __future__ import annotations

import enum
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import rclpy
from action_msgs.msg import GoalStatus
from qtree_relocation_msgs.action import RelocateObject, TrainPlanner
from qtree_relocation_msgs.srv import PlanFeasibility
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions

from qtree_task_planner.executive.replicas import ReplicaOracle
from qtree_task_planner.task_planner_node import ServiceOracle, train_goal
from relocation_app.graph import wait_for_interfaces
from relocation_common.feasibility import Label, replica_services
from relocation_common.node import ActionClient, call, check_type_support

FEASIBILITY = "/motion_planner/plan_feasibility"
TRAIN = "/task_planner/train"
RELOCATE = "/motion_planner/relocate"
CLOSE_CANCEL_WAIT = 2.0  # s: how long close() waits for the server to accept the cancel of a goal in flight


class ClientError(RuntimeError):
    """A server missing, a feasibility request refused, or no answer in time; the message says which."""


class TaskResult(enum.Enum):
    """How a goal ended, as nav2_simple_commander's TaskResult; ABORTED is the action's own 'aborted' status
    (action_msgs/GoalStatus), REJECTED a goal the server refused (bad fields: its log says why)."""

    SUCCEEDED = "succeeded"
    CANCELED = "canceled"
    ABORTED = "aborted"
    REJECTED = "rejected"


_STATUS = {GoalStatus.STATUS_SUCCEEDED: TaskResult.SUCCEEDED, GoalStatus.STATUS_CANCELED: TaskResult.CANCELED,
           GoalStatus.STATUS_ABORTED: TaskResult.ABORTED}


@dataclass(frozen=True)
class GoalResult:
    """The end of one goal: its status, a message (the Result's `message`, else the status), and the action's
    Result message (TrainPlanner.Result or RelocateObject.Result; None for a rejected goal)."""

    status: TaskResult
    message: str
    result: Any = None

    @property
    def succeeded(self) -> bool:
        """True when the server ended the goal as succeeded."""
        return self.status is TaskResult.SUCCEEDED


class RelocationClient:
    """One node talking to the graph: the feasibility service (Eq. 11), the TrainPlanner and RelocateObject
    actions, one goal in flight at a time. `context`: an initialised rclpy Context to use (left running), else a
    Context of its own on `domain_id` (default: ROS_DOMAIN_ID), shut down by close(). A context manager."""

    def __init__(self, name: str = "relocation_client", context: Context | None = None,
                 domain_id: int | None = None) -> None:
        if context is not None and domain_id is not None:
            raise ValueError("domain_id is for the client's own context: the context given has its domain already")
        if context is not None and not context.ok():
            raise ClientError("the context given is not initialised: call rclpy.init(context=...) first")
        check_type_support()  # InterfaceMismatch: a field of these messages would be lost silently
        self._own_context = context is None
        self.context = Context() if context is None else context
        if self._own_context:
            rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self.node = rclpy.create_node(name, context=self.context)
        except Exception:
            self._shutdown_context()
            raise
        # a deep request queue: a burst of questions is never dropped in this process (default depth 10)
        self._feasibility = self.node.create_client(PlanFeasibility, FEASIBILITY, qos_profile=QoSProfile(depth=1000))
        self._train = ActionClient(self.node, TrainPlanner, TRAIN)
        self._relocate = ActionClient(self.node, RelocateObject, RELOCATE)
        self._executor = SingleThreadedExecutor(context=self.context)
        self._executor.add_node(self.node)
        self._closed = False
        self._thread = threading.Thread(target=self._spin, name=name, daemon=True)
        self._thread.start()
        self._goal: Any = None  # ClientGoalHandle of the goal in flight
        self._result_future: Any = None
        self._rejected: GoalResult | None = None
        self._feedback: Any = None
        self._on_feedback: Callable[[Any], None] | None = None

    def _spin(self) -> None:
        """Spin until close(). An error while close() shuts the executor down is its end, not a failure: rclpy's
        shutdown can destroy a guard condition the spinning thread is adding to its wait set (ros2/rclpy#968;
        "AttributeError: 'NoneType' object has no attribute 'handle'" in one full test run under load)."""
        try:
            self._executor.spin()
        except ExternalShutdownException:
            pass
        except Exception:
            if self.context.ok() and not self._closed:
                raise

    # -- readiness ------------------------------------------------------------------------------------------
    def wait_until_ready(self, timeout: float = 120.0, check: Callable[[], None] = lambda: None) -> None:
        """Block until the feasibility service and both actions are served; ClientError after `timeout` s."""
        wait_for_interfaces(self.node, [(FEASIBILITY, PlanFeasibility)],
                            [(TRAIN, self._train), (RELOCATE, self._relocate)], timeout, check=check,
                            error=ClientError)

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
        question in flight per replica, failover when one dies (qtree_task_planner.executive.replicas); its
        `what_if({id: (x, y)})` asks the same questions on the scene with those objects elsewhere on the top shelf
        (what would follow a push)."""
        return ReplicaOracle([ServiceOracle(self.node.create_client(PlanFeasibility, name,
                                                                    qos_profile=QoSProfile(depth=1000)),
                                            timeout, margin, connect_wait=timeout)
                              for name in replica_services(FEASIBILITY, replicas)])

    # -- goals ----------------------------------------------------------------------------------------------
    def train(self, on_feedback: Callable[[Any], None] | None = None, timeout: float = 30.0,
              check: Callable[[], None] = lambda: None, **fields) -> bool:
        """Send a TrainPlanner goal (fields as train_goal: unset ones are the node's parameters). True when
        accepted; False when rejected (result() then says so). `on_feedback(TrainPlanner.Feedback)` is called
        from the spin thread. ClientError when the server does not answer within `timeout` s."""
        return self._send(self._train, TRAIN, train_goal(**fields), on_feedback, timeout, check)

    def relocate(self, object_id: str, removed=(), on_feedback: Callable[[Any], None] | None = None,
                 timeout: float = 30.0, check: Callable[[], None] = lambda: None) -> bool:
        """Send a RelocateObject goal: pick `object_id`, carry it to slot len(removed), come home. True when
        accepted, as train()."""
        goal = RelocateObject.Goal(object_id=object_id, removed_ids=list(removed))
        return self._send(self._relocate, RELOCATE, goal, on_feedback, timeout, check)

    def _send(self, action: ActionClient, name: str, goal, on_feedback, timeout: float, check) -> bool:
        if self._in_flight():
            raise ClientError("a goal is already in flight: wait for it or cancel it first")
        self._goal = self._result_future = self._rejected = self._feedback = None
        self._on_feedback = on_feedback
        handle = self._wait(action.send_goal_async(goal, feedback_callback=self._take_feedback), timeout, check,
                            "goal response")
        if not handle.accepted:
            self._rejected = GoalResult(TaskResult.REJECTED, f"{name}: goal rejected (see the node's log for why)")
            return False
        self._goal, self._result_future = handle, handle.get_result_async()
        return True

    def _take_feedback(self, msg) -> None:
        self._feedback = msg.feedback
        if self._on_feedback is not None:
            self._on_feedback(msg.feedback)

    def _in_flight(self) -> bool:
        return self._result_future is not None and not self._result_future.done()

    def feedback(self) -> Any:
        """The latest feedback message of the last goal sent (TrainPlanner.Feedback or RelocateObject.Feedback),
        None before the first one arrives."""
        return self._feedback

    def is_done(self) -> bool:
        """True once the last goal sent has ended (or was rejected); False while it runs or when none was sent."""
        return self._rejected is not None or (self._result_future is not None and self._result_future.done())

    def result(self) -> GoalResult | None:
        """The GoalResult of the last goal sent once it has ended, else None."""
        if self._rejected is not None:
            return self._rejected
        if not self.is_done():
            return None
        response = self._result_future.result()  # the action's GetResult response: status and result
        status = _STATUS.get(response.status)
        if status is None:
            return GoalResult(TaskResult.ABORTED, f"the goal ended with status {response.status}", response.result)
        return GoalResult(status, getattr(response.result, "message", "") or status.value, response.result)

    def wait(self, timeout: float, check: Callable[[], None] = lambda: None) -> GoalResult:
        """Block until the last goal sent ends; its GoalResult. ClientError when none was sent or after `timeout` s
        (the goal keeps running: cancel() it if you give up)."""
        if self._rejected is None:
            if self._result_future is None:
                raise ClientError("no goal was sent")
            self._wait(self._result_future, timeout, check, "result")
        result = self.result()
        assert result is not None  # the future is done
        return result

    def abandon(self) -> None:
        """Forget the goal in flight without cancelling it: its server died, no result will come (a new goal can be
        sent to the server that replaced it)."""
        self._goal = self._result_future = self._rejected = self._feedback = None

    def cancel(self, timeout: float = 10.0) -> bool:
        """Ask the server to cancel the goal in flight and wait for its answer; True when it is canceling it
        (result() then ends as CANCELED, or as it ended if it ended first). False when no goal is in flight."""
        if not self._in_flight():
            return False
        response = self._wait(self._goal.cancel_goal_async(), timeout, lambda: None, "cancel response")
        return len(response.goals_canceling) > 0

    def _wait(self, future, timeout: float, check: Callable[[], None], what: str):
        deadline = time.monotonic() + timeout
        while not future.done():
            check()
            if not self.context.ok():
                raise ClientError(f"shutting down while waiting for the {what}")
            if time.monotonic() > deadline:
                raise ClientError(f"no {what} within {timeout:.0f} s")
            time.sleep(0.05)
        return future.result()

    # -- the end --------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Cancel a goal still in flight (waiting CLOSE_CANCEL_WAIT s at most), stop the spin thread, destroy the
        node and shut down the client's own context (not one given to it). Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._in_flight() and self.context.ok():
                try:
                    self.cancel(CLOSE_CANCEL_WAIT)
                except ClientError:
                    pass  # the server is gone or slow: closing goes on
        finally:
            self._executor.shutdown(timeout_sec=1.0)
            self._thread.join(timeout=5.0)
            if not self._thread.is_alive():  # destroying a node its executor still waits on can crash the process
                for action in (self._train, self._relocate):
                    action.destroy()  # rclpy's destroy_node leaves action clients, and they keep the node alive
                self.node.destroy_node()
            self._shutdown_context()

    def _shutdown_context(self) -> None:
        if self._own_context:
            rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> RelocationClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
